#pragma once
// libapriltag's families by name, with an RAII owner. Internal to tracking (includes apriltag).
#include <memory>
#include <string>

#include <apriltag/apriltag.h>

namespace previz::tracking::detail {

struct FamilyDeleter {
  void (*destroy)(apriltag_family_t*) = nullptr;
  void operator()(apriltag_family_t* f) const {
    if (f && destroy) destroy(f);
  }
};
using FamilyPtr = std::unique_ptr<apriltag_family_t, FamilyDeleter>;

// Throws Error naming the family when libapriltag has no such family.
FamilyPtr createFamily(const std::string& name);

}  // namespace previz::tracking::detail
