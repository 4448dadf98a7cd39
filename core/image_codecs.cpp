// PNG and JPEG through libpng and libjpeg-turbo, as OpenCV 4.6 drives them (detail/image_codecs.h).
// Each libpng / libjpeg call sequence below is the one of OpenCV 4.6.0's grfmt_png.cpp /
// grfmt_jpeg.cpp for the same case; where OpenCV runs code of its own instead, the image is left
// to OpenCV (nullopt). The libraries report errors by longjmp: every setjmp sits in a small
// function that owns no C++ object, so that no destructor is skipped.
#include "core/detail/image_codecs.h"

#include <csetjmp>
#include <cstdint>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <vector>

#include <jpeglib.h>
#include <png.h>
#include <zlib.h>

#include <opencv2/core.hpp>
#include <opencv2/imgcodecs.hpp>  // the IMREAD_* flag values only: imgcodecs is not linked

#include "core/error.h"

#ifndef JCS_EXTENSIONS
#error "previz reads and writes JPEG with libjpeg-turbo (JCS_EXT_BGR)"
#endif
#if __BYTE_ORDER__ != __ORDER_LITTLE_ENDIAN__
#error "PNG's 16-bit samples are swapped for a little-endian host below (OpenCV's !isBigEndian())"
#endif

namespace previz::detail {

namespace {

// OpenCV's limit or the value of its environment variable (loadsave.cpp reads them the same way).
std::uint64_t ioLimit(const char* variable, std::uint64_t fallback) {
  const char* v = std::getenv(variable);
  if (!v || !*v) return fallback;
  char* end = nullptr;
  const unsigned long long n = std::strtoull(v, &end, 10);
  return end && *end == '\0' && n > 0 ? n : fallback;
}

}  // namespace

const ImageLimits& imageLimits() {
  static const ImageLimits limits{ioLimit("OPENCV_IO_MAX_IMAGE_WIDTH", 1u << 20),
                                  ioLimit("OPENCV_IO_MAX_IMAGE_HEIGHT", 1u << 20),
                                  ioLimit("OPENCV_IO_MAX_IMAGE_PIXELS", 1ull << 30)};
  return limits;
}

cv::Size checkedImageSize(std::uint64_t width, std::uint64_t height) {
  const std::uint64_t max_width = imageLimits().width, max_height = imageLimits().height,
                      max_pixels = imageLimits().pixels;
  if (width == 0 || height == 0 || width > max_width || height > max_height || width * height > max_pixels)
    throw Error("image size " + std::to_string(width) + "x" + std::to_string(height) + " outside OpenCV's limits (1 to " +
                std::to_string(max_width) + "x" + std::to_string(max_height) + ", " + std::to_string(max_pixels) +
                " pixels; OPENCV_IO_MAX_IMAGE_WIDTH, _HEIGHT, _PIXELS)");
  return cv::Size(static_cast<int>(width), static_cast<int>(height));
}

namespace {

// ---- what cv::imread asks of a decoder (loadsave.cpp, imread_) ------------------------------

// The flags decoded here: IMREAD_UNCHANGED, or any mix of COLOR, ANYDEPTH, ANYCOLOR and
// IGNORE_ORIENTATION (not GDAL, not the REDUCED_* scales).
bool flagsHandled(int flags) {
  constexpr int kHandled = cv::IMREAD_COLOR | cv::IMREAD_ANYDEPTH | cv::IMREAD_ANYCOLOR | cv::IMREAD_IGNORE_ORIENTATION;
  return flags == cv::IMREAD_UNCHANGED || (flags >= 0 && (flags & ~kHandled) == 0);
}

bool appliesOrientation(int flags) {
  return flags != cv::IMREAD_UNCHANGED && (flags & cv::IMREAD_IGNORE_ORIENTATION) == 0;
}

// The type imread_ makes the image from the file's own type and the flags.
int requestedType(int file_type, int flags) {
  if (flags == cv::IMREAD_UNCHANGED) return file_type;
  int type = file_type;
  if ((flags & cv::IMREAD_ANYDEPTH) == 0) type = CV_MAKETYPE(CV_8U, CV_MAT_CN(type));
  if ((flags & cv::IMREAD_COLOR) != 0 || ((flags & cv::IMREAD_ANYCOLOR) != 0 && CV_MAT_CN(type) > 1))
    return CV_MAKETYPE(CV_MAT_DEPTH(type), 3);
  return CV_MAKETYPE(CV_MAT_DEPTH(type), 1);
}

cv::Size checkedSize(std::uint64_t width, std::uint64_t height) { return checkedImageSize(width, height); }

// ---- EXIF orientation (exif.cpp ExifReader, loadsave.cpp ApplyExifOrientation) ---------------

// The orientation tag OpenCV's ExifReader finds in a TIFF-structured EXIF block: 1 when it
// finds none. ExifReader parses the first IFD's entries in order and stops at the first that
// reads out of bounds, keeping what it parsed; an entry before the orientation that could stop
// it (a string or rational it reads out of bounds) makes the answer uncertain: nullopt, and the
// image goes to OpenCV.
std::optional<int> exifOrientation(const unsigned char* data, size_t size) {
  if (size < 4) return 1;  // the tag mark cannot be read: ExifReader gives up
  const bool intel = data[0] == 'I' && data[1] == 'I';
  if (!intel && !(data[0] == 'M' && data[1] == 'M')) {
    // Read as big-endian by ExifReader; 42 there would make it go on with an unknown order.
    return data[2] == 0 && data[3] == 42 ? std::nullopt : std::optional<int>(1);
  }
  struct OutOfBounds {};
  auto u16 = [&](std::uint64_t at) -> std::uint32_t {
    if (at + 1 >= size) throw OutOfBounds{};
    return intel ? data[at] | (data[at + 1] << 8) : (data[at] << 8) | data[at + 1];
  };
  auto u32 = [&](std::uint64_t at) -> std::uint32_t {
    if (at + 3 >= size) throw OutOfBounds{};
    const std::uint32_t a = data[at], b = data[at + 1], c = data[at + 2], d = data[at + 3];
    return intel ? a | (b << 8) | (c << 16) | (d << 24) : (a << 24) | (b << 16) | (c << 8) | d;
  };
  try {
    if (u16(2) != 42) return 1;
    std::uint64_t offset = u32(4);
    const std::uint32_t entries = u16(offset);
    offset += 2;
    for (std::uint32_t i = 0; i < entries; ++i, offset += 12) {
      const std::uint32_t tag = u16(offset);
      switch (tag) {
        case 0x0112:  // Orientation
          return static_cast<int>(u16(offset + 8));
        case 0x010E: case 0x010F: case 0x0110: case 0x0131: case 0x0132: case 0x8298: {  // strings
          const std::uint64_t n = u32(offset + 4);
          const std::uint64_t at = n > 4 ? u32(offset + 8) : offset + 8;
          if (at + n > size) return std::nullopt;
          break;
        }
        case 0x011A: case 0x011B: case 0x013E: case 0x013F: case 0x0211: case 0x0214: {  // rationals
          const std::uint64_t at = u32(offset + 8);
          if (at + 6 * 8 > size) return std::nullopt;  // up to six of them (ReferenceBlackWhite)
          break;
        }
        case 0x0128: case 0x0213:  // ResolutionUnit, YCbCrPositioning
          u16(offset + 8);
          break;
        default:
          break;
      }
    }
  } catch (const OutOfBounds&) {
    return 1;  // ExifReader stopped before any orientation
  }
  return 1;
}

// ExifTransform: 1 top-left (as stored) ... 8 left-bottom.
void applyOrientation(int orientation, cv::Mat& image) {
  switch (orientation) {
    case 2: cv::flip(image, image, 1); break;
    case 3: cv::flip(image, image, -1); break;
    case 4: cv::flip(image, image, 0); break;
    case 5: cv::transpose(image, image); break;
    case 6: cv::transpose(image, image); cv::flip(image, image, 1); break;
    case 7: cv::transpose(image, image); cv::flip(image, image, -1); break;
    case 8: cv::transpose(image, image); cv::flip(image, image, 0); break;
    default: break;
  }
}

// ---- PNG -------------------------------------------------------------------------------------

constexpr unsigned char kPngSignature[8] = {0x89, 'P', 'N', 'G', '\r', '\n', 0x1a, '\n'};
constexpr size_t kMessageSize = 256;

struct PngInput {
  const unsigned char* data = nullptr;
  size_t size = 0, pos = 0;
};

void pngReadBytes(png_structp png, png_bytep out, size_t n) {
  auto* in = static_cast<PngInput*>(png_get_io_ptr(png));
  if (in->pos + n > in->size) png_error(png, "PNG input buffer is incomplete");
  std::memcpy(out, in->data + in->pos, n);
  in->pos += n;
}

// libpng's errors end here (OpenCV's print them); warnings print as OpenCV's do.
void pngFail(png_structp png, png_const_charp message) {
  std::snprintf(static_cast<char*>(png_get_error_ptr(png)), kMessageSize, "%s", message);
  png_longjmp(png, 1);
}

struct PngRead {
  png_structp png = nullptr;
  png_infop info = nullptr, end = nullptr;
  PngInput input;
  char why[kMessageSize] = "";
  ~PngRead() { png_destroy_read_struct(&png, &info, &end); }
};

struct PngHeader {
  png_uint_32 width = 0, height = 0;
  int bit_depth = 0, color_type = 0;
  int type = -1;  // the file's type as PngDecoder::readHeader sees it
};

bool readPngHeader(PngRead& r, PngHeader& h) {
  if (setjmp(png_jmpbuf(r.png))) return false;
  png_set_read_fn(r.png, &r.input, pngReadBytes);
  png_read_info(r.png, r.info);
  png_get_IHDR(r.png, r.info, &h.width, &h.height, &h.bit_depth, &h.color_type, nullptr, nullptr, nullptr);
  if (h.bit_depth <= 8 || h.bit_depth == 16) {
    switch (h.color_type) {
      case PNG_COLOR_TYPE_RGB:
      case PNG_COLOR_TYPE_PALETTE: {
        png_bytep trans = nullptr;
        int num_trans = 0;
        png_color_16p trans_values = nullptr;
        png_get_tRNS(r.png, r.info, &trans, &num_trans, &trans_values);
        h.type = num_trans > 0 ? CV_8UC4 : CV_8UC3;
        break;
      }
      case PNG_COLOR_TYPE_GRAY_ALPHA:
      case PNG_COLOR_TYPE_RGB_ALPHA:
        h.type = CV_8UC4;
        break;
      default:
        h.type = CV_8UC1;
    }
    if (h.bit_depth == 16) h.type = CV_MAKETYPE(CV_16U, CV_MAT_CN(h.type));
  }
  return true;
}

bool readPngPixels(PngRead& r, const PngHeader& h, cv::Mat& image, png_bytepp rows) {
  if (setjmp(png_jmpbuf(r.png))) return false;
  const bool color = image.channels() > 1;
  if (image.depth() == CV_8U && h.bit_depth == 16)
    png_set_strip_16(r.png);
  else
    png_set_swap(r.png);
  if (image.channels() < 4)
    png_set_strip_alpha(r.png);
  else
    png_set_tRNS_to_alpha(r.png);
  if (h.color_type == PNG_COLOR_TYPE_PALETTE) png_set_palette_to_rgb(r.png);
  if ((h.color_type & PNG_COLOR_MASK_COLOR) == 0 && h.bit_depth < 8) png_set_expand_gray_1_2_4_to_8(r.png);
  if ((h.color_type & PNG_COLOR_MASK_COLOR) && color)
    png_set_bgr(r.png);
  else if (color)
    png_set_gray_to_rgb(r.png);
  else
    png_set_rgb_to_gray(r.png, 1, 0.299, 0.587);
  png_set_interlace_handling(r.png);
  png_read_update_info(r.png, r.info);
  png_read_image(r.png, rows);
  png_read_end(r.png, r.end);
  return true;
}

std::optional<cv::Mat> decodePng(const std::string& bytes, int flags) {
  PngRead r;
  r.input.data = reinterpret_cast<const unsigned char*>(bytes.data());
  r.input.size = bytes.size();
  r.png = png_create_read_struct(PNG_LIBPNG_VER_STRING, r.why, pngFail, nullptr);
  if (r.png) {
    r.info = png_create_info_struct(r.png);
    r.end = png_create_info_struct(r.png);
  }
  if (!r.png || !r.info || !r.end) throw Error("PNG: out of memory");
  PngHeader h;
  if (!readPngHeader(r, h)) throw Error(std::string("PNG: ") + r.why);
  if (h.type < 0) throw Error("PNG: bit depth " + std::to_string(h.bit_depth) + " is not one OpenCV reads");
  cv::Mat image(checkedSize(h.width, h.height), requestedType(h.type, flags));
  std::vector<png_bytep> rows(image.rows);
  for (int y = 0; y < image.rows; ++y) rows[y] = image.ptr(y);
  if (!readPngPixels(r, h, image, rows.data())) throw Error(std::string("PNG: ") + r.why);
  // An eXIf chunk, before or after the pixels: OpenCV rotates the image by its orientation.
  png_uint_32 exif_size = 0;
  png_bytep exif = nullptr;
  if (png_get_valid(r.png, r.info, PNG_INFO_eXIf))
    png_get_eXIf_1(r.png, r.info, &exif_size, &exif);
  else if (png_get_valid(r.png, r.end, PNG_INFO_eXIf))
    png_get_eXIf_1(r.png, r.end, &exif_size, &exif);
  if (exif && exif_size > 0 && appliesOrientation(flags)) {
    const std::optional<int> orientation = exifOrientation(exif, exif_size);
    if (!orientation) return std::nullopt;
    applyOrientation(*orientation, image);
  }
  return image;
}

struct PngWrite {
  png_structp png = nullptr;
  png_infop info = nullptr;
  std::string out;
  char why[kMessageSize] = "";
  ~PngWrite() { png_destroy_write_struct(&png, &info); }
};

void pngWriteBytes(png_structp png, png_bytep data, size_t n) {
  auto* out = static_cast<std::string*>(png_get_io_ptr(png));
  try {
    out->append(reinterpret_cast<const char*>(data), n);
  } catch (const std::exception&) {
    png_error(png, "out of memory");
  }
}

void pngFlush(png_structp) {}

// PngEncoder::write without parameters: filter SUB, zlib level 1 (Z_BEST_SPEED), strategy
// Z_RLE (OpenCV's IMWRITE_PNG_STRATEGY_RLE default).
bool writePng(PngWrite& w, const cv::Mat& image, png_bytepp rows) {
  if (setjmp(png_jmpbuf(w.png))) return false;
  png_set_write_fn(w.png, &w.out, pngWriteBytes, pngFlush);
  png_set_filter(w.png, PNG_FILTER_TYPE_BASE, PNG_FILTER_SUB);
  png_set_compression_level(w.png, Z_BEST_SPEED);
  png_set_compression_strategy(w.png, Z_RLE);
  const int channels = image.channels();
  png_set_IHDR(w.png, w.info, image.cols, image.rows, image.depth() == CV_8U ? 8 : 16,
               channels == 1 ? PNG_COLOR_TYPE_GRAY : channels == 3 ? PNG_COLOR_TYPE_RGB : PNG_COLOR_TYPE_RGBA,
               PNG_INTERLACE_NONE, PNG_COMPRESSION_TYPE_DEFAULT, PNG_FILTER_TYPE_DEFAULT);
  png_write_info(w.png, w.info);
  png_set_bgr(w.png);
  png_set_swap(w.png);
  png_write_image(w.png, rows);
  png_write_end(w.png, w.info);
  return true;
}

std::string encodePng(const cv::Mat& image) {
  PngWrite w;
  w.png = png_create_write_struct(PNG_LIBPNG_VER_STRING, w.why, pngFail, nullptr);
  if (w.png) w.info = png_create_info_struct(w.png);
  if (!w.png || !w.info) throw Error("PNG: out of memory");
  std::vector<png_bytep> rows(image.rows);
  for (int y = 0; y < image.rows; ++y) rows[y] = const_cast<png_bytep>(image.ptr(y));
  if (!writePng(w, image, rows.data())) throw Error(std::string("PNG: ") + w.why);
  return std::move(w.out);
}

// ---- JPEG ------------------------------------------------------------------------------------

struct JpegErrors {
  jpeg_error_mgr pub;
  std::jmp_buf jump;
  char why[JMSG_LENGTH_MAX];
};

// OpenCV's error_exit longjmps without a word; the message is kept here for the Error. Warnings
// ("Premature end of JPEG file": a truncated file decodes, grey below the cut) print as
// OpenCV's do.
void jpegFail(j_common_ptr cinfo) {
  auto* errors = reinterpret_cast<JpegErrors*>(cinfo->err);
  (*cinfo->err->format_message)(cinfo, errors->why);
  std::longjmp(errors->jump, 1);
}

struct JpegRead {
  jpeg_decompress_struct cinfo{};
  JpegErrors errors{};
  bool created = false;
  JpegRead() {
    cinfo.err = jpeg_std_error(&errors.pub);
    errors.pub.error_exit = jpegFail;
  }
  ~JpegRead() {
    if (created) jpeg_destroy_decompress(&cinfo);
  }
};

// JpegDecoder::readHeader; the source is the file's bytes in memory (jpeg_mem_src ends a
// truncated file as jpeg_stdio_src does).
bool readJpegHeader(JpegRead& r, const std::string& bytes) {
  if (setjmp(r.errors.jump)) return false;
  jpeg_create_decompress(&r.cinfo);
  r.created = true;
  jpeg_mem_src(&r.cinfo, reinterpret_cast<const unsigned char*>(bytes.data()), static_cast<unsigned long>(bytes.size()));
  jpeg_save_markers(&r.cinfo, JPEG_APP0 + 1, 0xffff);
  jpeg_read_header(&r.cinfo, TRUE);
  r.cinfo.scale_num = 1;
  r.cinfo.scale_denom = 1;
  jpeg_calc_output_dimensions(&r.cinfo);
  return true;
}

// JpegDecoder::readData for 1- and 3-component files: libjpeg-turbo converts to BGR or grey.
bool readJpegPixels(JpegRead& r, cv::Mat& image) {
  if (setjmp(r.errors.jump)) return false;
  if (image.channels() > 1) {
    r.cinfo.out_color_space = JCS_EXT_BGR;
    r.cinfo.out_color_components = 3;
  } else {
    r.cinfo.out_color_space = JCS_GRAYSCALE;
    r.cinfo.out_color_components = 1;
  }
  jpeg_start_decompress(&r.cinfo);
  for (int y = 0; y < image.rows; ++y) {
    JSAMPROW row = image.ptr<JSAMPLE>(y);
    jpeg_read_scanlines(&r.cinfo, &row, 1);
  }
  jpeg_finish_decompress(&r.cinfo);
  return true;
}

std::optional<cv::Mat> decodeJpeg(const std::string& bytes, int flags) {
  JpegRead r;
  if (!readJpegHeader(r, bytes)) throw Error(std::string("JPEG: ") + r.errors.why);
  const jpeg_decompress_struct& c = r.cinfo;
  // CMYK / YCCK: OpenCV converts to BGR with code of its own. No Huffman tables (Motion JPEG
  // frames, arithmetic coding): OpenCV installs its own copy of the standard ones.
  if (c.num_components != 1 && c.num_components != 3) return std::nullopt;
  if (!c.ac_huff_tbl_ptrs[0] && !c.ac_huff_tbl_ptrs[1] && !c.dc_huff_tbl_ptrs[0] && !c.dc_huff_tbl_ptrs[1])
    return std::nullopt;
  int orientation = 1;
  if (appliesOrientation(flags)) {
    // The first APP1 marker, read past its "Exif\0\0" (whatever it holds, as OpenCV does).
    for (jpeg_saved_marker_ptr m = c.marker_list; m; m = m->next) {
      if (m->marker != JPEG_APP0 + 1) continue;
      if (m->data_length > 6) {
        const std::optional<int> o = exifOrientation(m->data + 6, m->data_length - 6);
        if (!o) return std::nullopt;
        orientation = *o;
      }
      break;
    }
  }
  cv::Mat image(checkedSize(c.output_width, c.output_height),
                requestedType(c.num_components > 1 ? CV_8UC3 : CV_8UC1, flags));
  if (!readJpegPixels(r, image)) throw Error(std::string("JPEG: ") + r.errors.why);
  applyOrientation(orientation, image);
  return image;
}

struct JpegWrite {
  jpeg_compress_struct cinfo{};
  JpegErrors errors{};
  bool created = false;
  unsigned char* buffer = nullptr;  // jpeg_mem_dest's, malloc'ed
  unsigned long size = 0;
  JpegWrite() {
    cinfo.err = jpeg_std_error(&errors.pub);
    errors.pub.error_exit = jpegFail;
  }
  ~JpegWrite() {
    if (created) jpeg_destroy_compress(&cinfo);
    std::free(buffer);
  }
};

// JpegEncoder::write without parameters: quality 95 (baseline tables), libjpeg's defaults
// otherwise; BGR(A) given as libjpeg-turbo's BGR / BGRX instead of OpenCV's copy to RGB (the
// same samples reach the colour conversion).
bool writeJpeg(JpegWrite& w, const cv::Mat& image) {
  if (setjmp(w.errors.jump)) return false;
  jpeg_create_compress(&w.cinfo);
  w.created = true;
  jpeg_mem_dest(&w.cinfo, &w.buffer, &w.size);
  w.cinfo.image_width = image.cols;
  w.cinfo.image_height = image.rows;
  const int channels = image.channels();
  w.cinfo.input_components = channels;
  w.cinfo.in_color_space = channels == 1 ? JCS_GRAYSCALE : channels == 3 ? JCS_EXT_BGR : JCS_EXT_BGRX;
  jpeg_set_defaults(&w.cinfo);
  jpeg_set_quality(&w.cinfo, 95, TRUE);
  jpeg_start_compress(&w.cinfo, TRUE);
  for (int y = 0; y < image.rows; ++y) {
    JSAMPROW row = const_cast<JSAMPROW>(image.ptr<JSAMPLE>(y));
    jpeg_write_scanlines(&w.cinfo, &row, 1);
  }
  jpeg_finish_compress(&w.cinfo);
  return true;
}

std::string encodeJpeg(const cv::Mat& image) {
  JpegWrite w;
  if (!writeJpeg(w, image)) throw Error(std::string("JPEG: ") + w.errors.why);
  return std::string(reinterpret_cast<const char*>(w.buffer), w.size);
}

std::string lowerAscii(std::string s) {
  for (char& c : s)
    if (c >= 'A' && c <= 'Z') c = static_cast<char>(c - 'A' + 'a');
  return s;
}

}  // namespace

std::optional<cv::Mat> decodeImage(const std::string& bytes, int flags) {
  if (!flagsHandled(flags)) return std::nullopt;
  if (bytes.size() >= sizeof kPngSignature && std::memcmp(bytes.data(), kPngSignature, sizeof kPngSignature) == 0)
    return decodePng(bytes, flags);
  if (bytes.size() >= 3 && static_cast<unsigned char>(bytes[0]) == 0xFF && static_cast<unsigned char>(bytes[1]) == 0xD8 &&
      static_cast<unsigned char>(bytes[2]) == 0xFF)
    return decodeJpeg(bytes, flags);
  return std::nullopt;
}

std::optional<std::string> encodeImage(const std::string& ext, const cv::Mat& image) {
  const std::string e = lowerAscii(ext);
  const bool png = e == ".png";
  if (!png && e != ".jpg" && e != ".jpeg" && e != ".jpe") return std::nullopt;
  // imencode: 1, 3 or 4 channels; a depth the format cannot hold is converted to 8 bits.
  const int channels = image.channels();
  if (channels != 1 && channels != 3 && channels != 4)
    throw Error(std::to_string(channels) + " channels: " + e.substr(1) + " images hold 1, 3 or 4");
  cv::Mat pixels = image;
  if (!(image.depth() == CV_8U || (png && image.depth() == CV_16U))) image.convertTo(pixels, CV_8U);
  return png ? encodePng(pixels) : encodeJpeg(pixels);
}

}  // namespace previz::detail
