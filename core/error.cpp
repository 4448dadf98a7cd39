#include "core/error.h"

#include <sstream>

namespace previz {

std::string formatError(const std::string& message, const ErrorContext& c) {
  std::ostringstream s;
  if (!c.file.empty()) s << "file '" << c.file << "': ";
  if (!c.camera.empty()) s << "camera '" << c.camera << "': ";
  if (c.frame) s << "frame " << *c.frame << ": ";
  if (!c.field.empty()) s << "field '" << c.field << "': ";
  s << message;
  return s.str();
}

Error::Error(const std::string& message, ErrorContext context)
    : std::runtime_error(formatError(message, context)),
      message_(message),
      context_(std::move(context)) {}

}  // namespace previz
