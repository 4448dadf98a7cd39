// libapriltag family constructors by name.
#include <apriltag/tag16h5.h>
#include <apriltag/tag25h9.h>
#include <apriltag/tag36h11.h>
#include <apriltag/tagCircle21h7.h>
#include <apriltag/tagCircle49h12.h>
#include <apriltag/tagCustom48h12.h>
#include <apriltag/tagStandard41h12.h>
#include <apriltag/tagStandard52h13.h>

#include "core/error.h"
#include "tracking/detail/families.h"
#include "tracking/props.h"

namespace previz::tracking {

namespace {
struct FamilyEntry {
  const char* name;
  apriltag_family_t* (*create)();
  void (*destroy)(apriltag_family_t*);
};
const FamilyEntry kFamilies[] = {
    {"tag36h11", tag36h11_create, tag36h11_destroy},
    {"tag25h9", tag25h9_create, tag25h9_destroy},
    {"tag16h5", tag16h5_create, tag16h5_destroy},
    {"tagCircle21h7", tagCircle21h7_create, tagCircle21h7_destroy},
    {"tagCircle49h12", tagCircle49h12_create, tagCircle49h12_destroy},
    {"tagCustom48h12", tagCustom48h12_create, tagCustom48h12_destroy},
    {"tagStandard41h12", tagStandard41h12_create, tagStandard41h12_destroy},
    {"tagStandard52h13", tagStandard52h13_create, tagStandard52h13_destroy},
};
}  // namespace

const std::vector<std::string>& knownFamilies() {
  static const std::vector<std::string> names = [] {
    std::vector<std::string> n;
    for (const FamilyEntry& e : kFamilies) n.emplace_back(e.name);
    return n;
  }();
  return names;
}

bool isKnownFamily(const std::string& family) {
  for (const FamilyEntry& e : kFamilies)
    if (family == e.name) return true;
  return false;
}

namespace detail {
FamilyPtr createFamily(const std::string& name) {
  for (const FamilyEntry& e : kFamilies)
    if (name == e.name) return FamilyPtr(e.create(), FamilyDeleter{e.destroy});
  std::string known;
  for (const FamilyEntry& e : kFamilies) known += (known.empty() ? "" : ", ") + std::string(e.name);
  ErrorContext c;
  c.field = "family";
  throw Error("unknown AprilTag family '" + name + "' (libapriltag has " + known + ")", c);
}
}  // namespace detail

}  // namespace previz::tracking
