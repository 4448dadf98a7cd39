#pragma once
// Content checksums for the batch manifest and ledgers: 64-bit FNV-1a (Fowler–Noll–Vo), as 16
// hex digits. It detects changed inputs and damaged outputs; it is not a defence against
// someone forging a file.
#include <cstdint>
#include <filesystem>
#include <string>

namespace previz::batch {

class Fnv1a64 {
 public:
  void add(const void* data, size_t bytes);
  void add(const std::string& text) { add(text.data(), text.size()); }
  std::uint64_t value() const { return h_; }
  std::string hex() const;

 private:
  std::uint64_t h_ = 0xcbf29ce484222325ull;
};

std::string hashText(const std::string& text);
// Streams the file; throws Error naming the file when it cannot be read.
std::string hashFile(const std::filesystem::path& path);

}  // namespace previz::batch
