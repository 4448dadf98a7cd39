// FNV-1a 64 (see hash.h).
#include "batch/hash.h"

#include <cstdio>
#include <fstream>
#include <vector>

#include "core/error.h"

namespace previz::batch {

void Fnv1a64::add(const void* data, size_t bytes) {
  const unsigned char* p = static_cast<const unsigned char*>(data);
  std::uint64_t h = h_;
  for (size_t i = 0; i < bytes; ++i) {
    h ^= p[i];
    h *= 0x100000001b3ull;
  }
  h_ = h;
}

std::string Fnv1a64::hex() const {
  char text[17];
  std::snprintf(text, sizeof(text), "%016llx", static_cast<unsigned long long>(h_));
  return text;
}

std::string hashText(const std::string& text) {
  Fnv1a64 h;
  h.add(text);
  return h.hex();
}

std::string hashFile(const std::filesystem::path& path) {
  std::ifstream in(path, std::ios::binary);
  ErrorContext c;
  c.file = path.string();
  if (!in) throw Error("cannot open file to checksum", c);
  Fnv1a64 h;
  std::vector<char> buffer(1 << 20);
  while (in) {
    in.read(buffer.data(), static_cast<std::streamsize>(buffer.size()));
    const std::streamsize got = in.gcount();
    if (got > 0) h.add(buffer.data(), static_cast<size_t>(got));
  }
  if (in.bad()) throw Error("read error while checksumming", c);
  return h.hex();
}

}  // namespace previz::batch
