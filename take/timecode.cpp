#include "take/timecode.h"

#include <cctype>
#include <cmath>
#include <cstdio>
#include <sstream>

#include "core/error.h"

namespace previz::take {

namespace {

// "29.97", "25" rather than std::to_string's "29.970000".
std::string number(double value) {
  std::ostringstream s;
  s << value;
  return s.str();
}

// Reads a field of 'min_digits'..'max_digits' digits at text[pos], advancing pos.
std::optional<int> readDigits(const std::string& text, size_t& pos, size_t min_digits, size_t max_digits) {
  int value = 0;
  size_t n = 0;
  while (pos < text.size() && n < max_digits && std::isdigit(static_cast<unsigned char>(text[pos]))) {
    value = value * 10 + (text[pos] - '0');
    ++pos;
    ++n;
  }
  if (n < min_digits) return std::nullopt;
  return value;
}

int nominalRate(double fps) {
  if (!(fps > 0) || !std::isfinite(fps))
    throw Error("fps must be > 0 (got " + number(fps) + ")", fieldContext("timecode"));
  return static_cast<int>(std::lround(fps));
}

// Labels skipped at each minute not divisible by ten: 2 at 30 (29.97), 4 at 60 (59.94).
int droppedLabels(int nominal, bool drop_frame, double fps) {
  if (!drop_frame) return 0;
  if (nominal != 30 && nominal != 60)
    throw Error("drop-frame timecode needs 29.97 or 59.94 fps (got " + number(fps) + ")",
                fieldContext("timecode"));
  return nominal / 15;
}

}  // namespace

std::optional<Timecode> parseTimecode(const std::string& text) {
  Timecode tc;
  size_t pos = 0;
  const auto hours = readDigits(text, pos, 2, 2);
  if (!hours || pos >= text.size() || text[pos++] != ':') return std::nullopt;
  const auto minutes = readDigits(text, pos, 2, 2);
  if (!minutes || pos >= text.size() || text[pos++] != ':') return std::nullopt;
  const auto seconds = readDigits(text, pos, 2, 2);
  if (!seconds || pos >= text.size()) return std::nullopt;
  const char separator = text[pos++];
  if (separator != ':' && separator != ';' && separator != '.') return std::nullopt;
  const auto frames = readDigits(text, pos, 2, 3);
  if (!frames || pos != text.size()) return std::nullopt;
  if (*minutes >= 60 || *seconds >= 60) return std::nullopt;
  tc.hours = *hours;
  tc.minutes = *minutes;
  tc.seconds = *seconds;
  tc.frames = *frames;
  tc.drop_frame = separator != ':';
  return tc;
}

std::string formatTimecode(const Timecode& tc) {
  char buffer[32];
  std::snprintf(buffer, sizeof buffer, "%02d:%02d:%02d%c%02d", tc.hours, tc.minutes, tc.seconds,
                tc.drop_frame ? ';' : ':', tc.frames);
  return buffer;
}

long long timecodeToFrames(const Timecode& tc, double fps) {
  const int nominal = nominalRate(fps);
  const int drop = droppedLabels(nominal, tc.drop_frame, fps);
  if (tc.frames < 0 || tc.frames >= nominal)
    throw Error("frames field " + std::to_string(tc.frames) + " of " + formatTimecode(tc) +
                    " must be < the nominal rate " + std::to_string(nominal),
                fieldContext("timecode"));
  if (tc.hours < 0 || tc.minutes < 0 || tc.minutes >= 60 || tc.seconds < 0 || tc.seconds >= 60)
    throw Error("'" + formatTimecode(tc) + "' is not a timecode", fieldContext("timecode"));
  if (drop > 0 && tc.seconds == 0 && tc.frames < drop && tc.minutes % 10 != 0)
    throw Error("'" + formatTimecode(tc) + "' is a dropped drop-frame label", fieldContext("timecode"));
  const long long total_minutes = 60LL * tc.hours + tc.minutes;
  const long long labels = (total_minutes * 60 + tc.seconds) * nominal + tc.frames;
  return labels - drop * (total_minutes - total_minutes / 10);
}

Timecode framesToTimecode(long long frames, double fps, bool drop_frame) {
  const int nominal = nominalRate(fps);
  const int drop = droppedLabels(nominal, drop_frame, fps);
  if (frames < 0)
    throw Error("frame " + std::to_string(frames) + " is before 00:00:00:00", fieldContext("timecode"));
  long long labels = frames;
  if (drop > 0) {
    // Back from frames to labels: each ten minutes hold 9 minutes with 'drop' fewer frames.
    const long long per_minute = 60LL * nominal - drop;
    const long long per_ten_minutes = 600LL * nominal - 9LL * drop;
    const long long tens = frames / per_ten_minutes;
    const long long rest = frames % per_ten_minutes;
    labels += 9LL * drop * tens;
    if (rest > drop) labels += drop * ((rest - drop) / per_minute);
  }
  Timecode tc;
  tc.drop_frame = drop_frame;
  tc.frames = static_cast<int>(labels % nominal);
  tc.seconds = static_cast<int>(labels / nominal % 60);
  tc.minutes = static_cast<int>(labels / (60LL * nominal) % 60);
  tc.hours = static_cast<int>(labels / (3600LL * nominal));
  return tc;
}

}  // namespace previz::take
