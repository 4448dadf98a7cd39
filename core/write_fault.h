#pragma once
// Fault injection for soak tests (live/soak.h, "disk full"): while a hook is set, every
// writeFileAtomic (core/io.h) asks it first; when it answers true that write fails as on a full
// disk: half the bytes reach the temporary, write() gives ENOSPC, the temporary is removed and
// the Error ("write failed: No space left on device") names the file. The target is never
// touched. One hook for the process: set it before the writes start, clear it ({}) after.
#include <filesystem>
#include <functional>

namespace previz {

using WriteFaultHook = std::function<bool(const std::filesystem::path& target)>;
void setWriteFaultHook(WriteFaultHook hook);

}  // namespace previz
