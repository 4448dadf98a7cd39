// Numbered image sequences (see sequence.h).
#include "take/sequence.h"

#include <algorithm>
#include <cctype>
#include <cstdio>
#include <map>
#include <numeric>

#include "take/detail/files.h"

namespace previz::take {
namespace fs = std::filesystem;

namespace {

bool isDigit(char c) { return std::isdigit(static_cast<unsigned char>(c)) != 0; }

// The most digits a frame number has in a file name (frameOf, findSequences) or a pattern.
constexpr int kMaxFrameDigits = 15;

// The last run of digits of a file name (before its extension when the extension has none):
// [begin, end) into name, or {npos, npos}.
std::pair<size_t, size_t> lastDigitRun(const std::string& name) {
  size_t end = name.size();
  while (end > 0 && !isDigit(name[end - 1])) --end;
  if (end == 0) return {std::string::npos, std::string::npos};
  size_t begin = end;
  while (begin > 0 && isDigit(name[begin - 1])) --begin;
  return {begin, end};
}

}  // namespace

std::string SequencePattern::str() const {
  return prefix + (width > 0 ? "%0" + std::to_string(width) + "d" : "%d") + suffix;
}

std::string SequencePattern::fileName(long long frame) const {
  char digits[32];
  if (width > 0)
    std::snprintf(digits, sizeof(digits), "%0*lld", width, frame);
  else
    std::snprintf(digits, sizeof(digits), "%lld", frame);
  return prefix + digits + suffix;
}

std::optional<long long> SequencePattern::frameOf(const std::string& file_name) const {
  if (file_name.size() <= prefix.size() + suffix.size()) return std::nullopt;
  if (file_name.compare(0, prefix.size(), prefix) != 0) return std::nullopt;
  if (file_name.compare(file_name.size() - suffix.size(), suffix.size(), suffix) != 0) return std::nullopt;
  const std::string digits = file_name.substr(prefix.size(), file_name.size() - prefix.size() - suffix.size());
  if (digits.size() > static_cast<size_t>(kMaxFrameDigits) || !std::all_of(digits.begin(), digits.end(), isDigit)) return std::nullopt;
  const long long frame = std::stoll(digits);
  if (fileName(frame) != file_name) return std::nullopt;  // "01" is not what %d writes
  return frame;
}

std::optional<SequencePattern> parsePattern(const std::string& text) {
  std::optional<SequencePattern> out;
  const auto set = [&](size_t begin, size_t end, int width) {
    if (out) return false;  // a second field
    out = SequencePattern{text.substr(0, begin), text.substr(end), width};
    return true;
  };
  for (size_t i = 0; i < text.size();) {
    if (text[i] == '%') {
      size_t j = i + 1;
      bool zero = false;
      if (j < text.size() && text[j] == '0') {
        zero = true;
        ++j;
      }
      size_t k = j;
      while (k < text.size() && isDigit(text[k])) ++k;
      if (k >= text.size() || text[k] != 'd') {
        ++i;
        continue;
      }
      // A field wider than a frame number can be is not a frame field: "%0700888889d" made
      // every file name 700 MB (fuzz/take_strings.cpp), "%099999999999d" overflowed stoi.
      if (k - j > 2) return std::nullopt;
      const int width = k > j ? std::stoi(text.substr(j, k - j)) : 0;
      if (width > kMaxFrameDigits) return std::nullopt;
      if (!set(i, k + 1, zero ? width : 0)) return std::nullopt;
      i = k + 1;
    } else if (text[i] == '#') {
      size_t k = i;
      while (k < text.size() && text[k] == '#') ++k;
      if (k - i > static_cast<size_t>(kMaxFrameDigits)) return std::nullopt;
      if (!set(i, k, static_cast<int>(k - i))) return std::nullopt;
      i = k;
    } else {
      ++i;
    }
  }
  return out;
}

bool isImageExtension(const fs::path& path) {
  return detail::hasExtension(path, {".png", ".jpg", ".jpeg", ".tif", ".tiff", ".exr", ".bmp", ".ppm", ".pgm"});
}

std::vector<FoundSequence> findSequences(const fs::path& dir) {
  // Candidate patterns by (prefix, suffix): a padded one when every number of the group has the
  // same count of digits and one starts with 0 (or all have the same length > 1), else %d.
  std::map<std::pair<std::string, std::string>, std::vector<std::string>> groups;
  std::error_code ec;
  for (const auto& entry : fs::directory_iterator(dir, ec)) {
    if (!entry.is_regular_file(ec) || !isImageExtension(entry.path())) continue;
    const std::string name = entry.path().filename().string();
    const auto [begin, end] = lastDigitRun(name);
    if (begin == std::string::npos || end - begin > static_cast<size_t>(kMaxFrameDigits)) continue;
    groups[{name.substr(0, begin), name.substr(end)}].push_back(name.substr(begin, end - begin));
  }
  std::vector<FoundSequence> found;
  for (const auto& [key, numbers] : groups) {
    std::map<size_t, int> lengths;
    bool leading_zero = false;
    for (const std::string& d : numbers) {
      ++lengths[d.size()];
      leading_zero = leading_zero || (d.size() > 1 && d[0] == '0');
    }
    // Padded: the shortest length when a number has a leading zero (longer ones overflowed the
    // padding); one length > 1 for all: padded to it; else unpadded.
    int width = 0;
    if (leading_zero)
      width = static_cast<int>(lengths.begin()->first);
    else if (lengths.size() == 1 && lengths.begin()->first > 1)
      width = static_cast<int>(lengths.begin()->first);
    FoundSequence s;
    s.pattern = {key.first, key.second, width};
    for (const std::string& d : numbers) {
      const std::optional<long long> f = s.pattern.frameOf(key.first + d + key.second);
      if (f) s.frames.push_back(*f);
    }
    if (s.frames.empty()) continue;
    std::sort(s.frames.begin(), s.frames.end());
    found.push_back(std::move(s));
  }
  std::sort(found.begin(), found.end(), [](const FoundSequence& a, const FoundSequence& b) {
    if (a.frames.size() != b.frames.size()) return a.frames.size() > b.frames.size();
    return a.pattern.str() < b.pattern.str();
  });
  return found;
}

std::vector<long long> framesOf(const fs::path& dir, const SequencePattern& pattern) {
  std::vector<long long> frames;
  std::error_code ec;
  for (const auto& entry : fs::directory_iterator(dir, ec)) {
    if (!entry.is_regular_file(ec)) continue;
    if (const std::optional<long long> f = pattern.frameOf(entry.path().filename().string())) frames.push_back(*f);
  }
  std::sort(frames.begin(), frames.end());
  return frames;
}

SequenceGaps sequenceGaps(const std::vector<long long>& frames) {
  SequenceGaps g;
  if (frames.size() < 2) return g;
  long long step = 0;
  for (size_t i = 1; i < frames.size(); ++i) step = std::gcd(step, frames[i] - frames[i - 1]);
  g.step = std::max(1LL, step);
  // A sequence with most of its frames on a coarser grid but one odd frame has step 1: its
  // holes are then counted at step 1, which is what they are.
  g.missing_count = (frames.back() - frames.front()) / g.step + 1 - static_cast<long long>(frames.size());
  for (size_t i = 1; i < frames.size() && g.missing.size() < SequenceGaps::kListed; ++i)
    for (long long f = frames[i - 1] + g.step; f < frames[i] && g.missing.size() < SequenceGaps::kListed; f += g.step)
      g.missing.push_back(f);
  return g;
}

}  // namespace previz::take
