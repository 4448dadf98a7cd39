// board.json (core/board.h readBoard, previz's own JSON board description).
#include "core/board.h"
#include "fuzz/fuzz_common.h"

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, size_t size) {
  return previz::fuzz::guarded([&] {
    const previz::fuzz::TempPath file("board.json");
    previz::fuzz::writeBytes(file.path(), data, size);
    previz::readBoard(file.path());
  });
}
