#pragma once
// Numbered image sequences as studios name them: any prefix and suffix around one frame number,
// padded or not, any start, gaps allowed ("A001C003.1001.exr", "templeSR0001.png", "1.jpg",
// "plate_v002.0060.tif"). A pattern has exactly one printf field for the number: "%06d", "%d"
// (unpadded), or the VFX spelling "####" (= "%04d"), which patterns given by a user may use.
#include <filesystem>
#include <optional>
#include <string>
#include <vector>

namespace previz::take {

struct SequencePattern {
  std::string prefix, suffix;  // around the number, e.g. "A001C003." and ".exr"
  int width = 0;               // zero-padded digits; 0 = unpadded (%d)

  // "A001C003.%04d.exr"
  std::string str() const;
  std::string fileName(long long frame) const;
  // The frame number of a file name written with this pattern (exactly: "01.png" is not frame 1
  // of "%d.png", "12345.exr" is frame 12345 of "%04d.exr"), nullopt when it is not one.
  std::optional<long long> frameOf(const std::string& file_name) const;
};

// Parses "name.%04d.exr", "name.%d.exr", "name.####.exr" (one field). nullopt when the text has
// no frame field, more than one, or one wider than 15 digits.
std::optional<SequencePattern> parsePattern(const std::string& text);

// Image extensions a sequence may have (lower case, with the dot): .png .jpg .jpeg .tif .tiff
// .exr .bmp .ppm .pgm
bool isImageExtension(const std::filesystem::path& path);

struct FoundSequence {
  SequencePattern pattern;
  std::vector<long long> frames;  // ascending, what is really there
};

// Every numbered sequence of image files in a folder (not recursive), largest first (ties: by
// pattern text, so the order is reproducible). A file belongs to the pattern with its LAST run
// of digits as the number ("A001C003.1001.exr": prefix "A001C003.", frame 1001).
std::vector<FoundSequence> findSequences(const std::filesystem::path& dir);

// The frames of one pattern in a folder.
std::vector<long long> framesOf(const std::filesystem::path& dir, const SequencePattern& pattern);

// The step of a sparse sequence (the gcd of the differences: 0, 60, 120 -> 60; 1 for a single
// frame) and the frames missing on that grid between the first and the last: how many, and the
// first kListed of them.
struct SequenceGaps {
  static constexpr size_t kListed = 20;
  long long step = 1;
  long long missing_count = 0;
  std::vector<long long> missing;
};
SequenceGaps sequenceGaps(const std::vector<long long>& frames);

}  // namespace previz::take
