#pragma once
// Kalibr's YAML subset (core/rig_import.cpp's camchain.yaml, core/board.cpp's target yaml).
#include <filesystem>
#include <sstream>
#include <string>
#include <utility>
#include <vector>

#include "core/error.h"

namespace previz::detail {

// Kalibr's files (camchain.yaml, target yaml) use a YAML subset that OpenCV's FileStorage cannot
// read (no %YAML header; block lists at their key's indentation), so a small strict parser: block
// maps, block lists of flow values, flow lists [a, b, [c]] (continued over lines while a bracket
// is open, as PyYAML wraps them at 80 columns), plain and quoted scalars, '#' comments. Anything
// else is an Error naming the line.

struct YamlNode {
  enum class Kind { kNull, kScalar, kList, kMap } kind = Kind::kNull;
  std::string scalar;
  std::vector<YamlNode> items;
  std::vector<std::pair<std::string, YamlNode>> entries;
  int line = 0;

  const YamlNode* find(const std::string& key) const {
    for (const auto& [k, v] : entries)
      if (k == key) return &v;
    return nullptr;
  }
};

class YamlSubsetParser {
 public:
  YamlSubsetParser(const std::string& text, const std::filesystem::path& file) : file_(file) { split(text); }

  YamlNode parse() {
    if (lines_.empty()) throw Error("empty file", cameraFileContext(file_.string(), "", ""));
    YamlNode root = block(lines_[0].indent);
    if (pos_ < lines_.size()) fail(lines_[pos_].number, "unexpected indentation");
    return root;
  }

 private:
  struct Line {
    int indent;
    std::string text;
    int number;
  };

  [[noreturn]] void fail(int line, const std::string& what) const {
    throw Error("line " + std::to_string(line) + ": " + what + " (Kalibr YAML subset)",
                cameraFileContext(file_.string(), "", ""));
  }

  // Logical lines: comments and blank lines dropped, flow lists joined across lines.
  void split(const std::string& text) {
    std::istringstream in(text);
    std::string raw;
    int number = 0, depth = 0;
    while (std::getline(in, raw)) {
      ++number;
      if (!raw.empty() && raw.back() == '\r') raw.pop_back();
      char quote = 0;
      size_t end = raw.size();
      for (size_t i = 0; i < raw.size(); ++i) {
        const char ch = raw[i];
        if (quote) {
          if (ch == quote) quote = 0;
        } else if ((ch == '\'' || ch == '"') && (i == 0 || std::string(" [,").find(raw[i - 1]) != std::string::npos)) {
          quote = ch;  // a quoted scalar starts a token; an apostrophe inside a word is text
        } else if (ch == '#' && (i == 0 || raw[i - 1] == ' ' || raw[i - 1] == '\t')) {
          end = i;
          break;
        } else if (ch == '[') {
          ++depth;
        } else if (ch == ']') {
          --depth;
        }
      }
      std::string s = raw.substr(0, end);
      while (!s.empty() && (s.back() == ' ' || s.back() == '\t')) s.pop_back();
      const size_t first = s.find_first_not_of(' ');
      if (first == std::string::npos) continue;
      if (s[first] == '\t') fail(number, "tab in indentation");
      if (s.rfind("%YAML", 0) == 0 || s == "---") continue;  // directives and document start
      const bool continuing = !lines_.empty() && continuation_;
      if (continuing) {
        lines_.back().text += " " + s.substr(first);
      } else {
        lines_.push_back({static_cast<int>(first), s.substr(first), number});
      }
      if (depth < 0) fail(number, "unbalanced ']'");
      continuation_ = depth > 0;
    }
    if (continuation_) fail(number, "unclosed '['");
  }

  static bool isItem(const std::string& s) { return s == "-" || s.rfind("- ", 0) == 0; }

  YamlNode block(int indent) {
    return isItem(lines_[pos_].text) ? list(indent) : map(indent);
  }

  YamlNode map(int indent) {
    YamlNode node;
    node.kind = YamlNode::Kind::kMap;
    node.line = lines_[pos_].number;
    while (pos_ < lines_.size() && lines_[pos_].indent == indent && !isItem(lines_[pos_].text)) {
      const Line& l = lines_[pos_];
      size_t colon = std::string::npos;
      for (size_t i = 0; i < l.text.size(); ++i)
        if (l.text[i] == ':' && (i + 1 == l.text.size() || l.text[i + 1] == ' ')) {
          colon = i;
          break;
        }
      if (colon == std::string::npos || colon == 0) fail(l.number, "expected 'key: value'");
      std::string key = l.text.substr(0, colon);
      if (key.front() == '"' || key.front() == '\'') key = unquote(key, l.number);
      if (node.find(key)) fail(l.number, "duplicate key '" + key + "'");
      std::string rest = l.text.substr(colon + 1);
      rest.erase(0, rest.find_first_not_of(' ') == std::string::npos ? rest.size() : rest.find_first_not_of(' '));
      ++pos_;
      YamlNode value;
      value.line = l.number;
      if (!rest.empty()) {
        value = flowTop(rest, l.number);
      } else if (pos_ < lines_.size() && lines_[pos_].indent > indent) {
        value = block(lines_[pos_].indent);
      } else if (pos_ < lines_.size() && lines_[pos_].indent == indent && isItem(lines_[pos_].text)) {
        value = list(indent);  // YAML allows a key's block list at the key's own indentation
      }
      node.entries.emplace_back(std::move(key), std::move(value));
    }
    if (pos_ < lines_.size() && lines_[pos_].indent > indent) fail(lines_[pos_].number, "unexpected indentation");
    return node;
  }

  YamlNode list(int indent) {
    YamlNode node;
    node.kind = YamlNode::Kind::kList;
    node.line = lines_[pos_].number;
    while (pos_ < lines_.size() && lines_[pos_].indent == indent && isItem(lines_[pos_].text)) {
      const Line& l = lines_[pos_];
      std::string rest = l.text.substr(1);
      rest.erase(0, rest.find_first_not_of(' ') == std::string::npos ? rest.size() : rest.find_first_not_of(' '));
      if (rest.empty() || (rest.front() != '[' && rest.find(": ") != std::string::npos))
        fail(l.number, "only flow values ('- [a, b]' or '- value') are supported in lists");
      node.items.push_back(flowTop(rest, l.number));
      ++pos_;
    }
    if (pos_ < lines_.size() && lines_[pos_].indent > indent) fail(lines_[pos_].number, "unexpected indentation");
    return node;
  }

  std::string unquote(const std::string& s, int line) const {
    const char q = s.front();
    if (s.size() < 2 || s.back() != q) fail(line, "unterminated quoted string");
    std::string out;
    for (size_t i = 1; i + 1 < s.size(); ++i) {
      if (q == '"' && s[i] == '\\' && i + 2 < s.size()) out += s[++i];
      else if (q == '\'' && s[i] == '\'' && i + 2 < s.size() && s[i + 1] == '\'') out += s[++i];
      else out += s[i];
    }
    return out;
  }

  // A value after 'key:' or '- ': a flow list, a quoted or a plain scalar (the rest of the line).
  YamlNode flowTop(const std::string& s, int line) const {
    if (s.front() == '{') fail(line, "flow maps are not supported");
    if (s.front() != '[') {
      YamlNode n;
      n.kind = YamlNode::Kind::kScalar;
      n.line = line;
      n.scalar = (s.front() == '"' || s.front() == '\'') ? unquote(s, line) : s;
      return n;
    }
    size_t i = 0;
    YamlNode n = flow(s, i, line);
    while (i < s.size() && s[i] == ' ') ++i;
    if (i != s.size()) fail(line, "unexpected text after ']'");
    return n;
  }

  YamlNode flow(const std::string& s, size_t& i, int line) const {
    while (i < s.size() && s[i] == ' ') ++i;
    YamlNode n;
    n.line = line;
    if (i < s.size() && s[i] == '[') {
      n.kind = YamlNode::Kind::kList;
      ++i;
      while (true) {
        while (i < s.size() && s[i] == ' ') ++i;
        if (i >= s.size()) fail(line, "unclosed '['");
        if (s[i] == ']' && n.items.empty()) {
          ++i;
          break;
        }
        n.items.push_back(flow(s, i, line));
        while (i < s.size() && s[i] == ' ') ++i;
        if (i < s.size() && s[i] == ',') {
          ++i;
        } else if (i < s.size() && s[i] == ']') {
          ++i;
          break;
        } else {
          fail(line, "expected ',' or ']' in a list");
        }
      }
      return n;
    }
    n.kind = YamlNode::Kind::kScalar;
    if (i < s.size() && (s[i] == '"' || s[i] == '\'')) {
      const char q = s[i];
      const size_t close = s.find(q, i + 1);
      if (close == std::string::npos) fail(line, "unterminated quoted string");
      n.scalar = unquote(s.substr(i, close - i + 1), line);
      i = close + 1;
      return n;
    }
    const size_t stop = s.find_first_of(",]", i);
    n.scalar = s.substr(i, stop == std::string::npos ? std::string::npos : stop - i);
    while (!n.scalar.empty() && n.scalar.back() == ' ') n.scalar.pop_back();
    if (n.scalar.empty()) fail(line, "empty list item");
    i = stop == std::string::npos ? s.size() : stop;
    return n;
  }

  std::filesystem::path file_;
  std::vector<Line> lines_;
  bool continuation_ = false;
  size_t pos_ = 0;
};

}  // namespace previz::detail
