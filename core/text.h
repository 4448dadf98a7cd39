#pragma once
// Small text helpers shared by the pages previz writes (demo report, batch summary).
#include <string>

namespace previz {

// &, <, >, " as HTML entities: text from files and errors put into a page.
std::string htmlEscape(const std::string& s);

}  // namespace previz
