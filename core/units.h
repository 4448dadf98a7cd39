#pragma once
// Degrees and radians with one spelling across previz (issue 34). Radians inside, degrees only at
// the edges (CLI, reports, FreeD, OpenTrackIO; ARCHITECTURE.md "Conventions"). Written as
// x * 180 / pi and x * pi / 180, not x * (180 / pi): the rounding most of the code had, so the
// figures previz writes stay what they were to the last bit. Where a file keeps the factor as a
// constant (x * kDeg, rounding as x * (pi / 180)), it spells it radians(1.0) or degrees(1.0).
#include <cmath>

namespace previz {

constexpr double degrees(double rad) { return rad * 180.0 / M_PI; }
constexpr double radians(double deg) { return deg * M_PI / 180.0; }

}  // namespace previz
