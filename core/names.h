#pragma once
// Names previz gives things, once (issue 34): the files of a frame and the main camera.
#include <cstdio>
#include <string>

namespace previz {

// The stem previz writes a take frame's files under: frame 42 -> "000042" (printf "%06d"), as
// in cams/<camera>/000042.png, out/depth/000042.exr, truth/mesh/actor.000042.ply. Sequences a
// user brings may have any pattern (take/sequence.h); this is only what previz itself names.
inline std::string frameStem(int frame) {
  char stem[32];
  std::snprintf(stem, sizeof(stem), "%06d", frame);
  return stem;
}
// The same name as a sequence pattern (take/sequence.h parsePattern): the pattern previz writes
// a take's sequences with unless told otherwise.
inline constexpr const char* kFramePattern = "%06d";

// The main (film) camera. Its role in a rig (RigCamera::role, the other being "witness") and in
// take.json "roles" ({"main": "A"}):
inline constexpr const char* kMainRole = "main";
// and the name it has where nothing else names it: the synthetic studio's main camera, a take
// without "roles", the default of --camera options that mean the main camera.
inline constexpr const char* kMainCamera = "main";

}  // namespace previz
