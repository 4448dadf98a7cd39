#pragma once
// Small parsers shared by the subcommands.
#include <string>
#include <utility>

#include "core/error.h"

namespace previz::app {

// "1280x720" -> (1280, 720); throws Error naming the flag otherwise.
inline std::pair<int, int> parseSize(const std::string& text, const std::string& flag) {
  const auto x = text.find_first_of("xX");
  try {
    if (x != std::string::npos) {
      size_t used_w = 0, used_h = 0;
      const int w = std::stoi(text.substr(0, x), &used_w);
      const int h = std::stoi(text.substr(x + 1), &used_h);
      if (used_w == x && used_h == text.size() - x - 1 && w > 0 && h > 0) return {w, h};
    }
  } catch (const std::exception&) {
  }
  ErrorContext context;
  context.field = flag;
  throw Error("expected WIDTHxHEIGHT with positive integers, e.g. 1280x720 (got '" + text + "')",
              context);
}

}  // namespace previz::app
