#pragma once
// File lookups and name helpers the take module shares (take.cpp, clean_plate.cpp,
// stream_writer.cpp, sequence.cpp).
#include <algorithm>
#include <cctype>
#include <filesystem>
#include <initializer_list>
#include <string>

namespace previz::take::detail {

// Video and still extensions a camera's file may have, lower case (files match in any case:
// cameras write A001.MOV).
inline constexpr std::initializer_list<const char*> kVideoExtensions = {".mkv", ".mov", ".mp4", ".avi",
                                                                        ".mxf", ".webm", ".m4v"};
inline constexpr std::initializer_list<const char*> kStillExtensions = {".png", ".jpg", ".jpeg", ".tif",
                                                                        ".tiff", ".exr", ".bmp"};

inline std::string lower(std::string s) {
  std::transform(s.begin(), s.end(), s.begin(), [](unsigned char c) { return std::tolower(c); });
  return s;
}

// text with every 'from' replaced by 'to' ("{camera}" in a source pattern).
inline std::string replaceAll(std::string text, const std::string& from, const std::string& to) {
  for (size_t at = text.find(from); at != std::string::npos; at = text.find(from, at + to.size()))
    text.replace(at, from.size(), to);
  return text;
}

inline bool hasExtension(const std::filesystem::path& p, std::initializer_list<const char*> extensions) {
  const std::string ext = lower(p.extension().string());
  return std::any_of(extensions.begin(), extensions.end(), [&](const char* e) { return ext == e; });
}

// The file 'stem'.<one of the extensions> in 'dir' (extension in any case), the earliest
// extension of the list winning; empty when there is none.
inline std::filesystem::path findByStem(const std::filesystem::path& dir, const std::string& stem,
                                        std::initializer_list<const char*> extensions) {
  std::filesystem::path best;
  size_t best_rank = extensions.size();
  std::error_code ec;
  for (const auto& entry : std::filesystem::directory_iterator(dir, ec)) {
    const std::filesystem::path& p = entry.path();
    if (p.stem().string() != stem || !entry.is_regular_file(ec)) continue;
    const std::string ext = lower(p.extension().string());
    size_t rank = 0;
    for (const char* e : extensions) {
      if (ext == e && rank < best_rank) {
        best = p;
        best_rank = rank;
      }
      ++rank;
    }
  }
  return best;
}

}  // namespace previz::take::detail
