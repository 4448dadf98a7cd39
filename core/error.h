#pragma once
// One error policy for all of previz (STYLE.md rule 4): library code throws previz::Error,
// carrying what a person needs to act on it (file, camera, frame, field). The CLI catches it
// at the top, prints what(), exits non-zero. Never thrown across an OpenMP region.
#include <optional>
#include <stdexcept>
#include <string>

namespace previz {

struct ErrorContext {
  std::string file;    // path of the file involved, if any
  std::string camera;  // camera name, if any
  std::optional<int> frame;
  std::string field;   // JSON/YAML field or option name, if any
};

// The usual contexts: a file (and a field in it), or a field / option.
inline ErrorContext fileContext(const std::string& file, const std::string& field = {}) {
  ErrorContext c;
  c.file = file;
  c.field = field;
  return c;
}
// A file, a camera in it (or the camera it describes) and a field.
inline ErrorContext cameraFileContext(const std::string& file, const std::string& camera, const std::string& field) {
  ErrorContext c;
  c.file = file;
  c.camera = camera;
  c.field = field;
  return c;
}
inline ErrorContext fieldContext(const std::string& field) {
  ErrorContext c;
  c.field = field;
  return c;
}

class Error : public std::runtime_error {
 public:
  explicit Error(const std::string& message, ErrorContext context = {});
  const ErrorContext& context() const { return context_; }
  const std::string& message() const { return message_; }

 private:
  std::string message_;
  ErrorContext context_;
};

// Formats "file 'x': camera 'c': frame 12: field 'fx': message" leaving out empty parts.
std::string formatError(const std::string& message, const ErrorContext& context);

}  // namespace previz
