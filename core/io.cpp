#include "core/io.h"

#include <fcntl.h>
#include <unistd.h>

#include <algorithm>
#include <atomic>
#include <cerrno>
#include <cmath>
#include <cstdio>
#include <cstdint>
#include <cstring>
#include <fstream>
#include <limits>
#include <map>
#include <mutex>
#include <optional>
#include <set>
#include <sstream>
#include <thread>

#include <OpenEXR/ImfChannelList.h>
#include <OpenEXR/ImfFrameBuffer.h>
#include <OpenEXR/ImfHeader.h>
#include <OpenEXR/ImfInputFile.h>
#include <Imath/half.h>
#include <OpenEXR/ImfOutputFile.h>
#include <OpenEXR/ImfStdIO.h>
#include <OpenEXR/ImfStringAttribute.h>
#include <OpenEXR/ImfTimeCodeAttribute.h>

#include "core/detail/image_codecs.h"
#include "core/detail/imgcodecs_plugin.h"
#include "core/error.h"
#include "core/plugin.h"
#include "core/write_fault.h"

namespace fs = std::filesystem;

namespace previz {

namespace {

// Where the original channel order is kept: OpenEXR lists channels alphabetically.
constexpr const char* kChannelOrderAttribute = "previz:channels";

std::string joinNames(const std::vector<std::string>& names) {
  std::string s;
  for (size_t i = 0; i < names.size(); ++i) s += (i ? "," : "") + names[i];
  return s;
}

std::vector<std::string> splitNames(const std::string& s) {
  std::vector<std::string> out;
  std::string item;
  std::istringstream in(s);
  while (std::getline(in, item, ',')) out.push_back(item);
  return out;
}

std::atomic<std::uint64_t> imgcodecs_calls{0};

const detail::ImgcodecsPlugin& imgcodecs() {
  ++imgcodecs_calls;
  return pluginInterface<detail::ImgcodecsPlugin>("previz_imgcodecs", "previz_imgcodecs_plugin",
                                                  "image formats other than PNG, JPEG and EXR: OpenCV's imgcodecs");
}

std::mutex& writeFaultMutex() {
  static std::mutex m;
  return m;
}
WriteFaultHook& writeFault() {
  static WriteFaultHook hook;
  return hook;
}

// Whether the write fault hook (setWriteFaultHook) fails this write.
bool injectedWriteFault(const fs::path& path) {
  std::lock_guard<std::mutex> lock(writeFaultMutex());
  return writeFault() && writeFault()(path);
}

}  // namespace

std::uint64_t detail::imgcodecsPluginCalls() { return imgcodecs_calls.load(); }

void setWriteFaultHook(WriteFaultHook hook) {
  std::lock_guard<std::mutex> lock(writeFaultMutex());
  writeFault() = std::move(hook);
}

void writeFileAtomic(const fs::path& path, const std::string& bytes) {
  if (path.empty() || path.filename().empty())
    throw Error("cannot write: the path names no file", fileContext(path));
  const fs::path parent = path.parent_path();
  std::error_code ec;
  if (!parent.empty()) {
    fs::create_directories(parent, ec);
    if (ec) throw Error("cannot create folder '" + parent.string() + "': " + ec.message(), fileContext(path));
  }
  // A unique temporary beside the target (same file system, so rename is atomic); unique per
  // process, thread and call so concurrent writers of one target never share a temporary.
  static std::atomic<unsigned long> counter{0};
  std::ostringstream tmp_name;
  tmp_name << "." << path.filename().string() << ".tmp." << ::getpid() << "."
           << std::hash<std::thread::id>{}(std::this_thread::get_id()) % 100000 << "."
           << counter.fetch_add(1);
  const fs::path tmp = parent / tmp_name.str();

  const int fd = ::open(tmp.c_str(), O_WRONLY | O_CREAT | O_TRUNC | O_CLOEXEC, 0644);
  if (fd < 0)
    throw Error(std::string("cannot create temporary file: ") + std::strerror(errno), fileContext(path));
  const char* p = bytes.data();
  size_t left = bytes.size();
  // An injected full disk (setWriteFaultHook): half the bytes go in, then ENOSPC.
  const size_t fail_at = injectedWriteFault(path) ? bytes.size() / 2 : bytes.size() + 1;
  for (;;) {
    const size_t written = bytes.size() - left;
    if (left == 0 && written < fail_at) break;
    ssize_t n = -1;
    if (written >= fail_at) errno = ENOSPC;
    else n = ::write(fd, p, std::min(left, fail_at - written));
    if (n < 0) {
      if (errno == EINTR) continue;
      const int e = errno;
      ::close(fd);
      fs::remove(tmp, ec);
      throw Error(std::string("write failed: ") + std::strerror(e), fileContext(path));
    }
    p += n;
    left -= static_cast<size_t>(n);
  }
  // fsync before rename: otherwise a power cut can leave the new name pointing at no data.
  if (::fsync(fd) != 0 || ::close(fd) != 0) {
    const int e = errno;
    fs::remove(tmp, ec);
    throw Error(std::string("cannot flush file: ") + std::strerror(e), fileContext(path));
  }
  fs::rename(tmp, path, ec);
  if (ec) {
    std::error_code ec2;
    fs::remove(tmp, ec2);
    throw Error("cannot rename temporary into place: " + ec.message(), fileContext(path));
  }
}

void writeJsonAtomic(const fs::path& path, const nlohmann::json& j, int indent) {
  writeFileAtomic(path, j.dump(indent) + "\n");
}

std::string encodeImage(const fs::path& path, const cv::Mat& image) {
  if (image.empty()) throw Error("cannot write an empty image", fileContext(path));
  const std::string ext = path.extension().string();
  if (ext.empty()) throw Error("no file extension to choose the image format", fileContext(path));
  try {
    if (std::optional<std::string> bytes = detail::encodeImage(ext, image)) return std::move(*bytes);
  } catch (const Error& e) {
    throw Error("cannot encode image as '" + ext + "': " + e.message(), fileContext(path));
  }
  std::vector<unsigned char> buf;
  bool ok = false;
  try {
    ok = imgcodecs().encode(ext, image, buf);
  } catch (const Error& e) {
    throw Error("cannot encode image as '" + ext + "': " + e.message(), fileContext(path));
  } catch (const cv::Exception& e) {
    throw Error("cannot encode image as '" + ext + "': " + e.what(), fileContext(path));
  }
  if (!ok) throw Error("cannot encode image as '" + ext + "'", fileContext(path));
  return std::string(buf.begin(), buf.end());
}

void writeImageAtomic(const fs::path& path, const cv::Mat& image) {
  writeFileAtomic(path, encodeImage(path, image));
}

std::string readTextFile(const fs::path& path) {
  std::error_code ec;
  if (!fs::exists(path, ec)) throw Error("file does not exist", fileContext(path));
  if (fs::is_directory(path, ec)) throw Error("is a folder, expected a file", fileContext(path));
  std::ifstream in(path, std::ios::binary);
  if (!in) throw Error(std::string("cannot open file: ") + std::strerror(errno), fileContext(path));
  std::ostringstream s;
  s << in.rdbuf();
  if (in.bad()) throw Error("read failed", fileContext(path));
  return s.str();
}

nlohmann::json readJsonFile(const fs::path& path) {
  const std::string text = readTextFile(path);
  try {
    return nlohmann::json::parse(text);
  } catch (const nlohmann::json::exception& e) {
    // parse_error, and out_of_range 406 for a number beyond double (1e999), which escaped
    // without the file's name (fuzz/: rig_json, board_json, props_json, ... PREVIZ_FUZZ_STRICT).
    throw Error(std::string("not valid JSON: ") + e.what(), fileContext(path));
  }
}

std::optional<int> jsonInt(const nlohmann::json& v) {
  if (v.is_number_unsigned()) {
    const auto u = v.get<std::uint64_t>();
    if (u <= static_cast<std::uint64_t>(std::numeric_limits<int>::max())) return static_cast<int>(u);
  } else if (v.is_number_integer()) {
    const auto i = v.get<std::int64_t>();
    if (i >= std::numeric_limits<int>::min() && i <= std::numeric_limits<int>::max()) return static_cast<int>(i);
  } else if (v.is_number_float()) {
    const double d = v.get<double>();
    if (d == std::floor(d) && d >= std::numeric_limits<int>::min() && d <= std::numeric_limits<int>::max())
      return static_cast<int>(d);
  }
  return std::nullopt;
}

int jsonInt(const nlohmann::json& v, const ErrorContext& context) {
  if (const std::optional<int> i = jsonInt(v)) return *i;
  std::string shown = v.dump();
  if (shown.size() > 40) shown = shown.substr(0, 37) + "...";
  throw Error("expected an integer that fits an int, got " + shown, context);
}

std::vector<int> jsonInts(const nlohmann::json& v, const ErrorContext& context) {
  if (!v.is_array()) throw Error(std::string("expected an array of integers, got ") + v.type_name(), context);
  std::vector<int> out;
  out.reserve(v.size());
  for (const nlohmann::json& e : v) out.push_back(jsonInt(e, context));
  return out;
}

cv::Mat readImage(const fs::path& path, int flags) {
  std::error_code ec;
  if (!fs::exists(path, ec)) throw Error("image file does not exist", fileContext(path));
  if (fs::is_directory(path, ec)) throw Error("is a folder, expected an image file", fileContext(path));
  const std::string unreadable = "not a readable image (corrupt, truncated or unsupported format)";
  try {
    if (std::optional<cv::Mat> image = detail::decodeImage(readTextFile(path), flags)) return std::move(*image);
  } catch (const Error& e) {
    throw Error(unreadable + ": " + e.message(), fileContext(path));
  }
  cv::Mat image;
  try {
    image = imgcodecs().read(path.string(), flags);
  } catch (const Error& e) {
    throw Error(unreadable + ": " + e.message(), fileContext(path));
  } catch (const cv::Exception& e) {
    throw Error(std::string("cannot decode image: ") + e.what(), fileContext(path));
  }
  if (image.empty()) throw Error(unreadable, fileContext(path));
  return image;
}

void writeExr(const fs::path& path, const ExrImage& exr) {
  const cv::Mat& img = exr.image;
  if (img.empty()) throw Error("cannot write an empty EXR image", fileContext(path));
  if (img.depth() != CV_32F)
    throw Error("EXR images must be CV_32F (float channels)", fileContext(path));
  const int n = img.channels();
  if (static_cast<int>(exr.channels.size()) != n)
    throw Error("EXR: " + std::to_string(n) + " channels in the image but " +
                    std::to_string(exr.channels.size()) + " names",
                fileContext(path));
  std::set<std::string> unique(exr.channels.begin(), exr.channels.end());
  if (unique.size() != exr.channels.size() || unique.count(""))
    throw Error("EXR channel names must be distinct and non-empty", fileContext(path));

  try {
    Imf::Header header(img.cols, img.rows);
    header.compression() = Imf::ZIP_COMPRESSION;
    const Imf::PixelType file_type = exr.half ? Imf::HALF : Imf::FLOAT;
    for (const auto& name : exr.channels) header.channels().insert(name, Imf::Channel(file_type));
    for (const auto& [key, value] : exr.attributes) {
      if (key == kChannelOrderAttribute) continue;
      header.insert(key, Imf::StringAttribute(value));
    }
    header.insert(kChannelOrderAttribute, Imf::StringAttribute(joinNames(exr.channels)));
    if (!exr.timecode.empty()) {
      int h = 0, m = 0, sec = 0, f = 0;
      char sep = ':';
      if (std::sscanf(exr.timecode.c_str(), "%d:%d:%d%c%d", &h, &m, &sec, &sep, &f) != 5 || h < 0 || h > 23 ||
          m < 0 || m > 59 || sec < 0 || sec > 59 || f < 0 || f > 59 || (sep != ':' && sep != ';'))
        throw Error("EXR timecode must be HH:MM:SS:FF (got '" + exr.timecode + "')", fileContext(path, "timeCode"));
      header.insert("timeCode", Imf::TimeCodeAttribute(Imf::TimeCode(h, m, sec, f, sep == ';')));
    }

    Imf::FrameBuffer fb;
    // OpenEXR does not convert FLOAT pixels to HALF on output: convert here, row-major.
    std::vector<Imath::half> halves;
    if (exr.half) {
      halves.reserve(img.total() * n);
      for (int y = 0; y < img.rows; ++y) {
        const float* row = img.ptr<float>(y);
        for (int i = 0; i < img.cols * n; ++i) halves.emplace_back(row[i]);
      }
      char* base = reinterpret_cast<char*>(halves.data());
      for (int c = 0; c < n; ++c)
        fb.insert(exr.channels[c], Imf::Slice(Imf::HALF, base + c * sizeof(Imath::half),
                                              n * sizeof(Imath::half),
                                              img.cols * n * sizeof(Imath::half)));
    } else {
      char* base = const_cast<char*>(reinterpret_cast<const char*>(img.data));
      for (int c = 0; c < n; ++c)
        fb.insert(exr.channels[c], Imf::Slice(Imf::FLOAT, base + c * sizeof(float),
                                              n * sizeof(float), img.step[0]));
    }
    Imf::StdOSStream out;
    {
      Imf::OutputFile file(out, header);
      file.setFrameBuffer(fb);
      file.writePixels(img.rows);
    }
    writeFileAtomic(path, out.str());
  } catch (const Error&) {
    throw;
  } catch (const std::exception& e) {
    throw Error(std::string("cannot write EXR: ") + e.what(), fileContext(path));
  }
}

namespace {

// OpenEXR 3.1 sizes each header attribute as the file declares before reading it (a string
// attribute claiming 2 GB in a 610-byte file: TypedAttribute<std::string>::readValueFrom
// allocated 2 GB; fuzz/exr.cpp, fuzz/corpus/exr/oom-attribute-size.exr). The headers are walked
// first (magic, version, then per attribute: name\0 type\0 int32 size, value; an empty name
// ends a header; multi-part files have several, ended by an empty one) and every size checked
// against the file's length.
//
// The walk must step through the header exactly as Imf::Header::readFrom does, or the two part
// ways and OpenEXR reads a size this walk never saw (fuzz/corpus/exr/oom-string-attribute.exr:
// a channel list declaring 55 bytes, where OpenEXR reads its channels up to the empty name, 56
// bytes, and so found a 2 GB string one byte on). OpenEXR reads a known type's value by the
// type, not by the declared size: fixed-size types their own bytes, "chlist" up to its empty
// name, "preview" 8 + 4 w h bytes (allocated first), "stringvector" length-prefixed strings.
// So the declared size of a known type must equal what OpenEXR will read, and every length
// inside a value must fit in it: a file OpenEXR wrote always passes.
namespace exr_walk {

std::int32_t int32At(const unsigned char* b) {
  return static_cast<std::int32_t>(std::uint32_t{b[0]} | std::uint32_t{b[1]} << 8 | std::uint32_t{b[2]} << 16 |
                                   std::uint32_t{b[3]} << 24);
}

// Bytes OpenEXR 3.1 reads for a fixed-size attribute type; -1 for the types read another way
// (string, stringvector, floatvector, chlist, preview, idmanifest) and for unknown types
// (OpaqueAttribute: the declared size).
int fixedSize(const std::string& type) {
  static const std::map<std::string, int> sizes = {
      {"box2i", 16},          {"box2f", 16},   {"chromaticities", 32}, {"compression", 1}, {"deepImageState", 1},
      {"double", 8},          {"envmap", 1},   {"float", 4},           {"int", 4},         {"keycode", 28},
      {"lineOrder", 1},       {"m33f", 36},    {"m33d", 72},           {"m44f", 64},       {"m44d", 128},
      {"rational", 8},        {"tiledesc", 9}, {"timecode", 8},        {"v2i", 8},         {"v2f", 8},
      {"v2d", 16},            {"v3i", 12},     {"v3f", 12},            {"v3d", 24}};
  const auto it = sizes.find(type);
  return it == sizes.end() ? -1 : it->second;
}

// Why a value of a type OpenEXR reads by its content does not fill its declared size exactly;
// empty when it does.
std::string contentMismatch(const std::string& type, const std::string& value) {
  const auto* b = reinterpret_cast<const unsigned char*>(value.data());
  const std::size_t size = value.size();
  if (type == "chlist") {  // per channel: name\0, then 16 bytes; an empty name ends the list
    std::size_t at = 0;
    for (;;) {
      const std::size_t nul = value.find('\0', at);
      if (nul == std::string::npos || nul - at > 255) return "a channel name without its end";
      if (nul == at) return nul + 1 == size ? "" : "the channel list ends before its declared size";
      at = nul + 1 + 16;
      if (at > size) return "a channel cut short";
    }
  }
  if (type == "preview") {  // unsigned width, height, then 4 bytes a pixel
    if (size < 8) return "shorter than its width and height";
    const std::uint64_t w = static_cast<std::uint32_t>(int32At(b)), h = static_cast<std::uint32_t>(int32At(b + 4));
    return 8 + 4 * w * h == size ? "" : "its pixels are not its declared size";
  }
  if (type == "stringvector") {  // int32 length, then the bytes, up to the declared size
    for (std::size_t at = 0; at < size;) {
      if (size - at < 4) return "a string length cut short";
      const std::int32_t n = int32At(b + at);
      at += 4;
      if (n < 0 || static_cast<std::size_t>(n) > size - at) return "a string longer than the attribute";
      at += static_cast<std::size_t>(n);
    }
    return "";
  }
  return "";
}

}  // namespace exr_walk

void checkExrHeaders(const fs::path& path) {
  std::ifstream in(path, std::ios::binary);
  in.seekg(0, std::ios::end);
  const std::int64_t length = in.tellg();
  in.seekg(0);
  unsigned char start[8];
  if (!in.read(reinterpret_cast<char*>(start), 8))
    throw Error("not an EXR file (shorter than its header)", fileContext(path));
  if (start[0] != 0x76 || start[1] != 0x2f || start[2] != 0x31 || start[3] != 0x01)
    throw Error("not an EXR file (no magic number)", fileContext(path));
  const bool multipart = (start[5] & 0x10) != 0;  // version field bit 12
  // OpenEXR reads a name of up to Name::MAX_LENGTH (255) characters and its end.
  const auto readName = [&](std::string& name) {
    name.clear();
    for (char c; in.get(c);) {
      if (c == '\0') return true;
      if (name.size() >= 255) return false;
      name += c;
    }
    return false;
  };
  for (;;) {  // headers
    std::string name, type;
    int attributes = 0;
    for (;; ++attributes) {
      if (!readName(name)) throw Error("EXR header cut short or malformed", fileContext(path));
      if (name.empty()) break;
      unsigned char size_le[4];
      if (!readName(type) || !in.read(reinterpret_cast<char*>(size_le), 4))
        throw Error("EXR header cut short or malformed (attribute '" + name + "')", fileContext(path));
      const std::int32_t size = exr_walk::int32At(size_le);
      if (size < 0 || static_cast<std::int64_t>(in.tellg()) + size > length)
        throw Error("EXR attribute '" + name + "' declares " + std::to_string(size) +
                        " bytes, more than the file holds",
                    fileContext(path));
      const int fixed = exr_walk::fixedSize(type);
      if (fixed >= 0 && size != fixed)
        throw Error("EXR attribute '" + name + "' of type " + type + " declares " + std::to_string(size) +
                        " bytes where its type has " + std::to_string(fixed),
                    fileContext(path));
      if (type == "chlist" || type == "preview" || type == "stringvector") {
        std::string value(static_cast<std::size_t>(size), '\0');
        if (!in.read(value.data(), size))
          throw Error("EXR header cut short (attribute '" + name + "')", fileContext(path));
        const std::string why = exr_walk::contentMismatch(type, value);
        if (!why.empty())
          throw Error("EXR attribute '" + name + "' of type " + type + " is malformed: " + why, fileContext(path));
      } else {
        in.seekg(size, std::ios::cur);
      }
    }
    if (!multipart || attributes == 0) return;
  }
}

}  // namespace

ExrImage readExr(const fs::path& path) {
  std::error_code ec;
  if (!fs::exists(path, ec)) throw Error("EXR file does not exist", fileContext(path));
  ExrImage exr;
  // OpenEXR allocates line-offset tables and tile buffers from the header while opening, before
  // the check below: its own limits (unlimited by default) are set to OpenCV's once, so that a
  // header declaring a huge image or tile fails in the constructor (fuzz/exr.cpp).
  static const bool limited = [] {
    const detail::ImageLimits& l = detail::imageLimits();
    const auto side = [](std::uint64_t v) {
      return static_cast<int>(std::min<std::uint64_t>(v, std::numeric_limits<int>::max()));
    };
    Imf::Header::setMaxImageSize(side(l.width), side(l.height));
    Imf::Header::setMaxTileSize(side(l.width), side(l.height));
    return true;
  }();
  (void)limited;
  checkExrHeaders(path);
  try {
    Imf::InputFile file(path.c_str());
    const Imf::Header& header = file.header();
    const Imath::Box2i dw = header.dataWindow();
    // The data window within OpenCV's image limits before anything is allocated: a 600-byte
    // file declaring a huge window made this allocate and zero gigabytes, and max - min + 1
    // could overflow int (fuzz/exr.cpp).
    const std::int64_t w64 = std::int64_t{dw.max.x} - dw.min.x + 1, h64 = std::int64_t{dw.max.y} - dw.min.y + 1;
    if (w64 <= 0 || h64 <= 0) throw Error("EXR data window is empty", fileContext(path));
    cv::Size size;
    try {
      size = detail::checkedImageSize(static_cast<std::uint64_t>(w64), static_cast<std::uint64_t>(h64));
    } catch (const Error& e) {
      throw Error("EXR data window " + e.message(), fileContext(path));
    }
    const int width = size.width, height = size.height;

    std::vector<std::string> names;
    for (auto it = header.channels().begin(); it != header.channels().end(); ++it)
      names.push_back(it.name());
    std::string order;
    if (const auto* tc = header.findTypedAttribute<Imf::TimeCodeAttribute>("timeCode")) {
      const Imf::TimeCode& t = tc->value();
      char text[32];
      std::snprintf(text, sizeof(text), "%02d:%02d:%02d%c%02d", t.hours(), t.minutes(), t.seconds(),
                    t.dropFrame() ? ';' : ':', t.frame());
      exr.timecode = text;
    }
    for (auto it = header.begin(); it != header.end(); ++it) {
      const auto* s = dynamic_cast<const Imf::StringAttribute*>(&it.attribute());
      if (!s) continue;
      if (std::string(it.name()) == kChannelOrderAttribute) {
        order = s->value();
      } else {
        exr.attributes[it.name()] = s->value();
      }
    }
    // Restore the writer's order when it is recorded and consistent; otherwise RGBA first,
    // then the rest alphabetically.
    std::vector<std::string> recorded = splitNames(order);
    std::vector<std::string> sorted_rec = recorded, sorted_names = names;
    std::sort(sorted_rec.begin(), sorted_rec.end());
    std::sort(sorted_names.begin(), sorted_names.end());
    if (!order.empty() && sorted_rec == sorted_names) {
      names = recorded;
    } else {
      auto rank = [](const std::string& s) {
        static const char* rgba[] = {"R", "G", "B", "A"};
        for (int i = 0; i < 4; ++i)
          if (s == rgba[i]) return i;
        return 4;
      };
      std::stable_sort(names.begin(), names.end(), [&](const std::string& a, const std::string& b) {
        return rank(a) < rank(b);
      });
    }
    const int n = static_cast<int>(names.size());
    if (n < 1 || n > CV_CN_MAX) throw Error("EXR has no usable channels", fileContext(path));
    exr.channels = names;
    exr.image = cv::Mat(height, width, CV_32FC(n), cv::Scalar::all(0));
    Imf::FrameBuffer fb;
    // OpenEXR addresses the buffer with absolute data-window coordinates; Slice::Make takes the
    // window's first pixel and does that arithmetic itself (computing base = data - min here was
    // undefined pointer overflow for a window far from the origin; fuzz/exr.cpp).
    for (int c = 0; c < n; ++c)
      fb.insert(names[c], Imf::Slice::Make(Imf::FLOAT, exr.image.data + c * sizeof(float), dw, n * sizeof(float),
                                           exr.image.step[0]));
    file.setFrameBuffer(fb);
    file.readPixels(dw.min.y, dw.max.y);
  } catch (const Error&) {
    throw;
  } catch (const std::exception& e) {
    throw Error(std::string("cannot read EXR (corrupt or not an EXR file): ") + e.what(),
                fileContext(path));
  }
  return exr;
}

void writeDepthExr(const fs::path& path, const cv::Mat& depth_m,
                   std::map<std::string, std::string> attributes) {
  if (depth_m.empty() || depth_m.channels() != 1)
    throw Error("depth map must be a non-empty one-channel image", fileContext(path));
  ExrImage exr;
  if (depth_m.depth() == CV_32F) {
    exr.image = depth_m;
  } else if (depth_m.depth() == CV_64F) {
    depth_m.convertTo(exr.image, CV_32F);  // +inf stays +inf
  } else {
    throw Error("depth map must be CV_32F or CV_64F (metres)", fileContext(path));
  }
  exr.channels = {"Z"};
  attributes.emplace("previz:depth",
                     "metric z along the camera axis (not ray length), metres; +inf where empty");
  attributes.emplace("previz:pixel_origin", "pixel (0,0) is the centre of the top-left pixel");
  exr.attributes = std::move(attributes);
  writeExr(path, exr);
}

cv::Mat readDepthExr(const fs::path& path) {
  ExrImage exr = readExr(path);
  const auto it = std::find(exr.channels.begin(), exr.channels.end(), "Z");
  if (it == exr.channels.end())
    throw Error("depth EXR has no channel 'Z' (channels: " + joinNames(exr.channels) + ")",
                fileContext(path));
  if (exr.channels.size() == 1) return exr.image;
  cv::Mat z;
  cv::extractChannel(exr.image, z, static_cast<int>(it - exr.channels.begin()));
  return z;
}

}  // namespace previz
