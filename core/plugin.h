#pragma once
// Plugins: the parts of previz that need heavy libraries (FFmpeg and OpenCV's videoio for video,
// PCL for point clouds, OpenCV's imgcodecs for image formats other than PNG / JPEG / EXR) live in
// shared modules loaded with dlopen the first time they are needed, so that a command that does
// not need them does not pay for loading them (OpenCV's videoio alone brings 244 libraries).
// glibc has no lazy DT_NEEDED: a library the executable links is loaded at start-up, used or not.
//
// A plugin 'name' is the file <name>.so, looked for beside the running executable, in its lib/
// (the bundle of scripts/bundle.sh), in its ../lib (an installed tree; the build tree's
// build/lib), then, unless the executable has a lib/ beside it (a bundle is self-contained), in
// the build tree's plugin folder (the tests, which run from their own folders). Each plugin
// exports one C function
// `const void* <entry>(int version)` returning its interface, a struct of function pointers
// (core/detail/imgcodecs_plugin.h, take/detail/video_plugin.h, ...), or null when the caller was
// built against another version of that interface.
#include <string>
#include <vector>

// A plugin's entry function: `PREVIZ_PLUGIN_ENTRY const void* previz_video_plugin(int version)`.
// Plugins are built with hidden visibility (CMakeLists.txt, previz_add_plugin): this is all
// they export.
#define PREVIZ_PLUGIN_ENTRY extern "C" __attribute__((visibility("default")))

namespace previz {

// The address of 'symbol' in plugin 'name', loading the plugin on the first call (thread-safe;
// never unloaded). Throws Error naming the plugin's path when it is not found (every path
// tried), cannot be loaded (dlerror: e.g. a library it needs is missing) or lacks the symbol.
// 'purpose' says what it is for, in the message: "video files and live cameras".
void* pluginSymbol(const std::string& name, const char* symbol, const std::string& purpose);

// The interface of plugin 'name' from its entry function, for interface version 'version'.
// Throws Error naming the plugin's path as pluginSymbol does, and when the plugin was built
// with another version of the interface.
const void* pluginInterface(const std::string& name, const char* entry, int version, const std::string& purpose);

// Typed: Interface has a `static constexpr int kVersion`.
template <class Interface>
const Interface& pluginInterface(const std::string& name, const char* entry, const std::string& purpose) {
  return *static_cast<const Interface*>(pluginInterface(name, entry, Interface::kVersion, purpose));
}

// Whether plugin 'name' has been loaded by this process (tests: a command that needs no video
// must not load the video plugin).
bool pluginLoaded(const std::string& name);

// Where plugin 'name' is looked for, in order.
std::vector<std::string> pluginCandidates(const std::string& name);

}  // namespace previz
