#pragma once
// SMPTE timecode (SMPTE ST 12-1) as cameras and containers carry it: "HH:MM:SS:FF", and
// drop-frame "HH:MM:SS;FF" (or "HH:MM:SS.FF") for the NTSC rates 29.97 and 59.94, where the
// frame labels 0 and 1 (0..3 at 59.94) are skipped at the start of every minute not divisible
// by ten, so that the label keeps up with the wall clock (FFmpeg libavutil/timecode.c does the same).
#include <optional>
#include <string>

namespace previz::take {

struct Timecode {
  int hours = 0, minutes = 0, seconds = 0, frames = 0;
  bool drop_frame = false;
};

// "HH:MM:SS:FF" or "HH:MM:SS;FF" / "HH:MM:SS.FF" (drop frame); two digits each field (frames
// two or three, for rates above 100); minutes and seconds < 60. Anything else: nullopt. Whether
// the frames field fits a rate is checked where the rate is known (timecodeToFrames).
std::optional<Timecode> parseTimecode(const std::string& text);
// "01:00:00:05", "00:01:00;02".
std::string formatTimecode(const Timecode& tc);

// The frame count since 00:00:00:00 at the nominal rate round(fps). Drop frame needs a
// nominal rate of 30 or 60 (29.97, 59.94). Throws Error (field "timecode") when fps <= 0, the
// frames field is >= the nominal rate, or the label does not exist (a dropped label, or drop
// frame at another rate).
long long timecodeToFrames(const Timecode& tc, double fps);
// The inverse; frames >= 0. Throws Error (field "timecode") as above.
Timecode framesToTimecode(long long frames, double fps, bool drop_frame = false);

}  // namespace previz::take
