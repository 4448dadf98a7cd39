// OpenCV FileStorage cameras (core/camera_io.h readOpenCvCamera, core/rig_import.h importOpenCv):
// YAML (with or without the %YAML header), XML or JSON, picked from the first byte as a user's
// file extension would pick it.
#include "core/camera_io.h"
#include "core/rig_import.h"
#include "fuzz/fuzz_common.h"

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, size_t size) {
  size_t first = 0;
  while (first < size && (data[first] == ' ' || data[first] == '\n' || data[first] == '\t')) ++first;
  const char* ext = first < size && data[first] == '<' ? ".xml" : first < size && data[first] == '{' ? ".json" : ".yaml";
  const previz::fuzz::TempPath file(std::string("camera") + ext);
  previz::fuzz::writeBytes(file.path(), data, size);
  previz::fuzz::guarded([&] { previz::readOpenCvCamera(file.path()); });
  previz::fuzz::guarded([&] {
    previz::ImportOptions options;
    options.width = 640;
    options.height = 480;
    previz::importOpenCv({file.path()}, options);
  });
  return 0;
}
