#include "core/leftovers.h"

#include <unistd.h>

#include <fstream>
#include <iterator>
#include <optional>
#include <string>
#include <vector>

namespace previz {

namespace fs = std::filesystem;

namespace {

// The writer's pid when 'name' is one of the temporaries core/leftovers.h describes.
std::optional<long> temporaryPid(const std::string& name) {
  if (name.size() < 2 || name[0] != '.') return std::nullopt;
  for (const char* tag : {".tmp.", ".pcl."}) {
    const size_t at = name.rfind(tag);
    if (at == std::string::npos || at == 0) continue;
    const std::string rest = name.substr(at + 5);
    const size_t end = rest.find('.');
    const std::string digits = rest.substr(0, end);
    if (digits.empty() || digits.find_first_not_of("0123456789") != std::string::npos || digits.size() > 9) continue;
    return std::stol(digits);
  }
  return std::nullopt;
}

// A process that can still write: not gone, and not a zombie (a killed process stays in /proc
// until its parent reaps it, which for an orphan can take a while).
bool alive(long pid) {
  if (pid == static_cast<long>(::getpid())) return true;
  std::ifstream in("/proc/" + std::to_string(pid) + "/stat");
  if (!in) return false;
  std::string stat((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
  const size_t paren = stat.rfind(')');  // the command name may hold spaces and parentheses
  if (paren == std::string::npos || paren + 2 >= stat.size()) return true;
  const char state = stat[paren + 2];
  return state != 'Z' && state != 'X';
}

}  // namespace

int removeLeftoverTemporaries(const fs::path& dir, bool recursive) {
  std::error_code ec;
  if (!fs::is_directory(dir, ec)) return 0;
  std::vector<fs::path> stale;
  auto consider = [&](const fs::directory_entry& e) {
    std::error_code ec2;
    if (!e.is_regular_file(ec2)) return;
    const std::optional<long> pid = temporaryPid(e.path().filename().string());
    if (pid && !alive(*pid)) stale.push_back(e.path());
  };
  if (recursive) {
    for (fs::recursive_directory_iterator it(dir, fs::directory_options::skip_permission_denied, ec), end;
         !ec && it != end; it.increment(ec))
      consider(*it);
  } else {
    for (fs::directory_iterator it(dir, ec), end; !ec && it != end; it.increment(ec)) consider(*it);
  }
  int removed = 0;
  for (const fs::path& p : stale) removed += fs::remove(p, ec) ? 1 : 0;
  return removed;
}

}  // namespace previz
