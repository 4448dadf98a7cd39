// PNG and JPEG without OpenCV's imgcodecs (core/detail/image_codecs.h): every image read and
// every byte written must be what cv::imread / cv::imencode give (this test links imgcodecs to
// compare), on the real images of ../shared/data and on PNG / JPEG variants made here with libpng
// and libjpeg; other formats go to the previz_imgcodecs plugin, loaded only then.
#include <algorithm>
#include <csetjmp>
#include <cstdint>
#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <string>
#include <vector>

#include <jpeglib.h>
#include <png.h>

#include <gtest/gtest.h>
#include <opencv2/imgcodecs.hpp>
#include <opencv2/imgproc.hpp>

#include "core/detail/image_codecs.h"
#include "core/error.h"
#include "core/io.h"
#include "core/plugin.h"
#include "scratch.h"

namespace fs = std::filesystem;

namespace previz {
namespace {

// The flags previz reads with (IMREAD_UNCHANGED, GRAYSCALE, COLOR, ANYDEPTH | ANYCOLOR) and the
// other mixes imread_ distinguishes.
const int kFlags[] = {cv::IMREAD_UNCHANGED,
                      cv::IMREAD_GRAYSCALE,
                      cv::IMREAD_COLOR,
                      cv::IMREAD_ANYDEPTH,
                      cv::IMREAD_ANYCOLOR,
                      cv::IMREAD_ANYDEPTH | cv::IMREAD_ANYCOLOR,
                      cv::IMREAD_COLOR | cv::IMREAD_ANYDEPTH,
                      cv::IMREAD_COLOR | cv::IMREAD_IGNORE_ORIENTATION,
                      cv::IMREAD_ANYCOLOR | cv::IMREAD_IGNORE_ORIENTATION};

fs::path tmpDir(const std::string& name) { return test::scratchDir("image_codecs_test", name); }

// Images read or written through the previz_imgcodecs plugin since it was made: what this test
// did, whatever other tests of the same process loaded the plugin for before it.
struct PluginCalls {
  std::uint64_t start = detail::imgcodecsPluginCalls();
  std::uint64_t since() const { return detail::imgcodecsPluginCalls() - start; }
};

// Same type, size and bytes.
::testing::AssertionResult sameImage(const cv::Mat& a, const cv::Mat& b) {
  if (a.type() != b.type() || a.size() != b.size())
    return ::testing::AssertionFailure() << "type " << a.type() << " vs " << b.type() << ", size " << a.size()
                                         << " vs " << b.size();
  if (a.empty()) return ::testing::AssertionSuccess();
  cv::Mat diff;
  cv::absdiff(a.reshape(1), b.reshape(1), diff);
  const int differing = cv::countNonZero(diff);
  if (differing) return ::testing::AssertionFailure() << differing << " samples differ";
  return ::testing::AssertionSuccess();
}

void expectReadsAsOpenCv(const fs::path& file) {
  for (int flags : kFlags) {
    const cv::Mat theirs = cv::imread(file.string(), flags);
    ASSERT_FALSE(theirs.empty()) << file << " flags " << flags;
    EXPECT_TRUE(sameImage(readImage(file, flags), theirs)) << file << " flags " << flags;
  }
}

std::vector<fs::path> sharedImages(const std::vector<std::string>& extensions) {
  std::vector<fs::path> files;
  std::error_code ec;
  for (auto it = fs::recursive_directory_iterator(PREVIZ_SHARED_DATA, ec); it != fs::recursive_directory_iterator();
       ++it)
    for (const std::string& e : extensions)
      if (it->path().extension() == e) files.push_back(it->path());
  std::sort(files.begin(), files.end());
  return files;
}

// ---- PNG variants written with libpng ---------------------------------------------------------

struct PngVariant {
  std::string name;
  int color_type = PNG_COLOR_TYPE_RGB;
  int bit_depth = 8;
  bool trns = false;
  bool interlaced = false;
  int exif_orientation = 0;  // 0 = no eXIf chunk
};

// Random samples of the variant's layout, written through libpng as is.
void writePngVariant(const fs::path& path, const PngVariant& v, cv::RNG& rng) {
  const int w = 37, h = 23;
  const int channels = v.color_type == PNG_COLOR_TYPE_GRAY || v.color_type == PNG_COLOR_TYPE_PALETTE ? 1
                       : v.color_type == PNG_COLOR_TYPE_GRAY_ALPHA                                  ? 2
                       : v.color_type == PNG_COLOR_TYPE_RGB                                         ? 3
                                                                                                    : 4;
  const int row_bytes = (w * channels * v.bit_depth + 7) / 8;
  std::vector<unsigned char> data(static_cast<size_t>(row_bytes) * h);
  for (auto& b : data) b = static_cast<unsigned char>(rng.uniform(0, 256));
  if (v.color_type == PNG_COLOR_TYPE_PALETTE && v.bit_depth == 8)
    for (auto& b : data) b %= 16;  // indices within the palette
  FILE* f = std::fopen(path.c_str(), "wb");
  ASSERT_TRUE(f);
  png_structp png = png_create_write_struct(PNG_LIBPNG_VER_STRING, nullptr, nullptr, nullptr);
  png_infop info = png_create_info_struct(png);
  if (setjmp(png_jmpbuf(png))) {
    png_destroy_write_struct(&png, &info);
    std::fclose(f);
    FAIL() << "libpng could not write " << v.name;
  }
  png_init_io(png, f);
  png_set_IHDR(png, info, w, h, v.bit_depth, v.color_type, v.interlaced ? PNG_INTERLACE_ADAM7 : PNG_INTERLACE_NONE,
               PNG_COMPRESSION_TYPE_DEFAULT, PNG_FILTER_TYPE_DEFAULT);
  const int entries = std::min(16, 1 << v.bit_depth);  // every index the samples can hold
  std::vector<png_color> palette(entries);
  std::vector<png_byte> alphas(entries);
  if (v.color_type == PNG_COLOR_TYPE_PALETTE) {
    for (int i = 0; i < entries; ++i) {
      palette[i] = {static_cast<png_byte>(rng.uniform(0, 256)), static_cast<png_byte>(rng.uniform(0, 256)),
                    static_cast<png_byte>(rng.uniform(0, 256))};
      alphas[i] = static_cast<png_byte>(rng.uniform(0, 256));
    }
    png_set_PLTE(png, info, palette.data(), entries);
  }
  png_color_16 trans_colour{};
  trans_colour.gray = trans_colour.red = static_cast<png_uint_16>(data[0]);
  if (v.trns) png_set_tRNS(png, info, alphas.data(), v.color_type == PNG_COLOR_TYPE_PALETTE ? entries : 0, &trans_colour);
  std::vector<png_byte> exif;
  if (v.exif_orientation) {
    // A TIFF header (little-endian), one IFD entry: Orientation SHORT 1.
    exif = {'I', 'I', 42, 0, 8, 0, 0, 0, 1, 0, 0x12, 0x01, 3, 0, 1, 0, 0, 0,
            static_cast<png_byte>(v.exif_orientation), 0, 0, 0, 0, 0, 0, 0};
    png_set_eXIf_1(png, info, static_cast<png_uint_32>(exif.size()), exif.data());
  }
  png_write_info(png, info);
  std::vector<png_bytep> rows(h);
  for (int y = 0; y < h; ++y) rows[y] = data.data() + static_cast<size_t>(y) * row_bytes;
  png_write_image(png, rows.data());
  png_write_end(png, nullptr);
  png_destroy_write_struct(&png, &info);
  std::fclose(f);
}

TEST(ImageCodecs, PngVariantsReadAsOpenCvReadsThemWithEveryFlag) {
  const PluginCalls plugin;
  const fs::path dir = tmpDir("png_variants");
  std::vector<PngVariant> variants;
  for (int depth : {1, 2, 4, 8, 16}) variants.push_back({"grey" + std::to_string(depth), PNG_COLOR_TYPE_GRAY, depth});
  for (int depth : {1, 2, 4, 8})
    variants.push_back({"palette" + std::to_string(depth), PNG_COLOR_TYPE_PALETTE, depth});
  variants.push_back({"palette_trns", PNG_COLOR_TYPE_PALETTE, 8, true});
  variants.push_back({"grey_trns", PNG_COLOR_TYPE_GRAY, 8, true});
  variants.push_back({"rgb_trns", PNG_COLOR_TYPE_RGB, 8, true});
  for (int depth : {8, 16}) {
    const std::string d = std::to_string(depth);
    variants.push_back({"grey_alpha" + d, PNG_COLOR_TYPE_GRAY_ALPHA, depth});
    variants.push_back({"rgb" + d, PNG_COLOR_TYPE_RGB, depth});
    variants.push_back({"rgba" + d, PNG_COLOR_TYPE_RGB_ALPHA, depth});
    variants.push_back({"rgb_interlaced" + d, PNG_COLOR_TYPE_RGB, depth, false, true});
    variants.push_back({"grey_interlaced" + d, PNG_COLOR_TYPE_GRAY, depth, false, true});
  }
  for (int o = 1; o <= 8; ++o) variants.push_back({"exif" + std::to_string(o), PNG_COLOR_TYPE_RGB, 8, false, false, o});
  cv::RNG rng(31);
  for (const PngVariant& v : variants) {
    SCOPED_TRACE(v.name);
    const fs::path file = dir / (v.name + ".png");
    writePngVariant(file, v, rng);
    expectReadsAsOpenCv(file);
  }
  EXPECT_EQ(plugin.since(), 0u) << "PNG / JPEG went through OpenCV's imgcodecs";
}

// ---- JPEG variants ---------------------------------------------------------------------------

// 'jpeg' with an APP1 marker holding 'payload' inserted after SOI.
std::string withApp1(const std::string& jpeg, const std::string& payload) {
  const size_t length = payload.size() + 2;
  std::string marker = "\xFF\xE1";
  marker += static_cast<char>(length >> 8);
  marker += static_cast<char>(length & 0xFF);
  return jpeg.substr(0, 2) + marker + payload + jpeg.substr(2);
}

// "Exif\0\0" and a TIFF header with one IFD entry, Orientation = 'orientation', preceded by a
// Make string entry (ASCII, 6 bytes at an offset) as cameras write it.
std::string exifBlock(int orientation, bool intel) {
  std::string tiff;
  auto u16 = [&](int v) {
    const char a = static_cast<char>(v & 0xFF), b = static_cast<char>((v >> 8) & 0xFF);
    tiff += intel ? std::string{a, b} : std::string{b, a};
  };
  auto u32 = [&](unsigned v) {
    if (intel) {
      u16(v & 0xFFFF);
      u16(v >> 16);
    } else {
      u16(v >> 16);
      u16(v & 0xFFFF);
    }
  };
  tiff += intel ? "II" : "MM";
  u16(42);
  u32(8);
  u16(2);  // entries
  u16(0x010F);  // Make, ASCII, 6 bytes at 38
  u16(2);
  u32(6);
  u32(38);
  u16(0x0112);  // Orientation, SHORT, 1
  u16(3);
  u32(1);
  u16(orientation);
  u16(0);
  u32(0);  // no next IFD
  tiff += std::string("Camr1\0", 6);
  return std::string("Exif\0\0", 6) + tiff;
}

std::string encoded(const std::string& ext, const cv::Mat& image, const std::vector<int>& params = {}) {
  std::vector<unsigned char> buf;
  EXPECT_TRUE(cv::imencode(ext, image, buf, params));
  return std::string(buf.begin(), buf.end());
}

// A CMYK JPEG (Adobe, inverted as Photoshop writes it): OpenCV converts it with its own code.
std::string cmykJpeg(const cv::Mat& cmyk) {
  jpeg_compress_struct c{};
  jpeg_error_mgr err{};
  c.err = jpeg_std_error(&err);
  jpeg_create_compress(&c);
  unsigned char* buffer = nullptr;
  unsigned long size = 0;
  jpeg_mem_dest(&c, &buffer, &size);
  c.image_width = cmyk.cols;
  c.image_height = cmyk.rows;
  c.input_components = 4;
  c.in_color_space = JCS_CMYK;
  jpeg_set_defaults(&c);
  jpeg_start_compress(&c, TRUE);
  for (int y = 0; y < cmyk.rows; ++y) {
    JSAMPROW row = const_cast<JSAMPROW>(cmyk.ptr<JSAMPLE>(y));
    jpeg_write_scanlines(&c, &row, 1);
  }
  jpeg_finish_compress(&c);
  jpeg_destroy_compress(&c);
  std::string out(reinterpret_cast<const char*>(buffer), size);
  std::free(buffer);
  return out;
}

TEST(ImageCodecs, JpegVariantsReadAsOpenCvReadsThemWithEveryFlag) {
  const PluginCalls plugin;
  const fs::path dir = tmpDir("jpeg_variants");
  cv::RNG rng(7);
  cv::Mat colour(41, 29, CV_8UC3), grey(41, 29, CV_8UC1);
  rng.fill(colour, cv::RNG::UNIFORM, 0, 256);
  cv::GaussianBlur(colour, colour, cv::Size(5, 5), 2);  // something like a photograph
  rng.fill(grey, cv::RNG::UNIFORM, 0, 256);
  std::vector<std::pair<std::string, std::string>> files = {
      {"colour", encoded(".jpg", colour)},
      {"grey", encoded(".jpg", grey)},
      {"progressive", encoded(".jpg", colour, {cv::IMWRITE_JPEG_PROGRESSIVE, 1})},
      {"optimized_q60", encoded(".jpg", colour, {cv::IMWRITE_JPEG_OPTIMIZE, 1, cv::IMWRITE_JPEG_QUALITY, 60})},
      {"xmp_app1", withApp1(encoded(".jpg", colour), std::string("http://ns.adobe.com/xap/1.0/\0<x/>", 33))},
  };
  for (int o = 1; o <= 8; ++o) {
    files.push_back({"exif_intel" + std::to_string(o), withApp1(encoded(".jpg", colour), exifBlock(o, true))});
    files.push_back({"exif_motorola" + std::to_string(o), withApp1(encoded(".jpg", grey), exifBlock(o, false))});
  }
  // Cut in the middle of the scan: libjpeg warns and fills the rest with grey, as OpenCV does.
  const std::string whole = encoded(".jpg", colour);
  files.push_back({"truncated", whole.substr(0, whole.size() / 2)});
  for (const auto& [name, bytes] : files) {
    SCOPED_TRACE(name);
    const fs::path file = dir / (name + ".jpg");
    writeFileAtomic(file, bytes);
    expectReadsAsOpenCv(file);
  }
  EXPECT_EQ(plugin.since(), 0u) << "PNG / JPEG went through OpenCV's imgcodecs";

  // CMYK: left to OpenCV's imgcodecs, in its plugin; the same image comes back.
  cv::Mat cmyk(19, 23, CV_8UC4);
  rng.fill(cmyk, cv::RNG::UNIFORM, 0, 256);
  writeFileAtomic(dir / "cmyk.jpg", cmykJpeg(cmyk));
  expectReadsAsOpenCv(dir / "cmyk.jpg");
  EXPECT_GT(plugin.since(), 0u);
  EXPECT_TRUE(pluginLoaded("previz_imgcodecs"));
}

TEST(ImageCodecs, RealImagesReadAsOpenCvReadsThem) {
  const PluginCalls plugin;
  const std::vector<fs::path> files = sharedImages({".png", ".jpg"});
  // ../shared/data holds 54 PNG and 55 JPEG files (find ../shared/data -name '*.png' | wc -l).
  ASSERT_GE(files.size(), 100u) << "real data missing under " << PREVIZ_SHARED_DATA;
  for (const fs::path& file : files) expectReadsAsOpenCv(file);
  EXPECT_EQ(plugin.since(), 0u) << "PNG / JPEG went through OpenCV's imgcodecs";
}

TEST(ImageCodecs, WrittenBytesAreOpenCvsForEveryDepthAndChannelCount) {
  const PluginCalls plugin;
  cv::RNG rng(3);
  std::vector<cv::Mat> images;
  for (int depth : {CV_8U, CV_16U, CV_16S, CV_32F})
    for (int channels : {1, 3, 4}) {
      cv::Mat m(31, 47, CV_MAKETYPE(depth, channels));
      rng.fill(m, cv::RNG::UNIFORM, 0, depth == CV_8U ? 256 : depth == CV_32F ? 300 : 65536);
      images.push_back(m);
    }
  // Smooth content, as the studio renders it, compresses differently from noise.
  cv::Mat smooth(120, 160, CV_8UC3);
  for (int y = 0; y < smooth.rows; ++y)
    for (int x = 0; x < smooth.cols; ++x) smooth.at<cv::Vec3b>(y, x) = cv::Vec3b(x, y, (x + y) / 2);
  images.push_back(smooth);
  images.push_back(smooth(cv::Rect(5, 7, 100, 50)));  // a non-continuous view
  for (const fs::path& real : sharedImages({".png"})) images.push_back(cv::imread(real.string(), cv::IMREAD_UNCHANGED));
  for (const cv::Mat& image : images) {
    for (const char* ext : {".png", ".PNG", ".jpg", ".jpeg"}) {
      SCOPED_TRACE(std::string(ext) + " type " + std::to_string(image.type()) + " " + std::to_string(image.cols) +
                   "x" + std::to_string(image.rows));
      EXPECT_EQ(encodeImage(std::string("x") + ext, image), encoded(ext, image));
    }
  }
  EXPECT_EQ(plugin.since(), 0u) << "PNG / JPEG went through OpenCV's imgcodecs";
  cv::Mat two(4, 4, CV_8UC2, cv::Scalar::all(1));
  EXPECT_THROW(encodeImage("two.png", two), Error);
}

TEST(ImageCodecs, OtherFormatsGoThroughTheImgcodecsPluginOnlyThen) {
  const PluginCalls plugin;
  const fs::path dir = tmpDir("other");
  cv::Mat image(21, 34, CV_8UC3);
  cv::randu(image, 0, 256);
  writeImageAtomic(dir / "a.png", image);
  EXPECT_TRUE(sameImage(readImage(dir / "a.png"), image));
  EXPECT_EQ(plugin.since(), 0u) << "PNG / JPEG went through OpenCV's imgcodecs";
  writeImageAtomic(dir / "a.bmp", image);
  EXPECT_GT(plugin.since(), 0u);
  EXPECT_TRUE(pluginLoaded("previz_imgcodecs"));
  EXPECT_EQ(readTextFile(dir / "a.bmp"), encoded(".bmp", image));
  expectReadsAsOpenCv(dir / "a.bmp");
  cv::Mat wide(9, 11, CV_16UC3);
  cv::randu(wide, 0, 65536);
  writeImageAtomic(dir / "wide.tif", wide);
  expectReadsAsOpenCv(dir / "wide.tif");
  EXPECT_TRUE(sameImage(readImage(dir / "wide.tif"), wide));
}

TEST(ImageCodecs, CorruptPngAndJpegNameTheFileAndTheReason) {
  const PluginCalls plugin;
  const fs::path dir = tmpDir("corrupt");
  cv::Mat image(32, 48, CV_8UC3);
  cv::randu(image, 0, 256);
  for (const char* ext : {".png", ".jpg"}) {
    const std::string bytes = encodeImage(std::string("x") + ext, image);
    const fs::path cut = dir / (std::string("header_only") + ext);
    writeFileAtomic(cut, bytes.substr(0, 20));
    try {
      readImage(cut);
      FAIL() << cut << " decoded";
    } catch (const Error& e) {
      EXPECT_EQ(e.context().file, cut.string());
      EXPECT_NE(std::string(e.what()).find("not a readable image"), std::string::npos) << e.what();
      EXPECT_NE(std::string(e.what()).find(ext[1] == 'p' ? "PNG" : "JPEG"), std::string::npos) << e.what();
    }
    EXPECT_TRUE(cv::imread(cut.string()).empty());  // as OpenCV: no image
  }
  EXPECT_EQ(plugin.since(), 0u) << "PNG / JPEG went through OpenCV's imgcodecs";
}

}  // namespace
}  // namespace previz
