#pragma once
// Small parsers shared by the subcommands.
#include <cmath>
#include <optional>
#include <sstream>
#include <string>
#include <utility>
#include <vector>

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
  throw Error("expected WIDTHxHEIGHT with positive integers, e.g. 1280x720 (got '" + text + "')",
              fieldContext(flag));
}

// "NAME=INTEGER" (e.g. "witness03=2") -> (NAME, INTEGER); throws Error naming the flag otherwise.
inline std::pair<std::string, int> parseNamedInt(const std::string& text, const std::string& flag) {
  const auto eq = text.find('=');
  if (eq != std::string::npos && eq > 0 && eq + 1 < text.size()) {
    try {
      size_t used = 0;
      const int value = std::stoi(text.substr(eq + 1), &used);
      if (used == text.size() - eq - 1) return {text.substr(0, eq), value};
    } catch (const std::exception&) {
    }
  }
  throw Error("expected NAME=INTEGER, e.g. witness03=2 (got '" + text + "')", fieldContext(flag));
}

// "a,b,,c" -> {a, b, c}: the non-empty items between the separators.
inline std::vector<std::string> splitList(const std::string& text, char sep = ',') {
  std::vector<std::string> out;
  std::stringstream in(text);
  for (std::string item; std::getline(in, item, sep);)
    if (!item.empty()) out.push_back(item);
  return out;
}

// 'text' read whole as one finite number; nullopt otherwise.
inline std::optional<double> finiteNumber(const std::string& text) {
  try {
    size_t used = 0;
    const double v = std::stod(text, &used);
    if (used == text.size() && std::isfinite(v)) return v;
  } catch (const std::exception&) {
  }
  return std::nullopt;
}

// One finite number, all of 'text'; throws Error naming the flag otherwise.
inline double parseNumber(const std::string& text, const std::string& flag) {
  if (const auto v = finiteNumber(text)) return *v;
  throw Error("expected a number (got '" + text + "')", fieldContext(flag));
}

// Exactly 'count' comma-separated finite numbers; otherwise an Error naming the flag that says
// "expected <form> (got '<text>')" (form: by default "<count> comma-separated numbers").
inline std::vector<double> parseNumbers(const std::string& text, size_t count,
                                        const std::string& flag, std::string form = {}) {
  if (form.empty()) form = std::to_string(count) + " comma-separated numbers";
  const auto bad = [&] { return Error("expected " + form + " (got '" + text + "')", fieldContext(flag)); };
  std::vector<double> values;
  std::stringstream in(text);
  for (std::string item; std::getline(in, item, ',');) {
    const auto v = finiteNumber(item);
    if (!v) throw bad();
    values.push_back(*v);
  }
  if (values.size() != count) throw bad();
  return values;
}

}  // namespace previz::app
