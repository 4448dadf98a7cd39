// Loading plugins (see plugin.h).
#include "core/plugin.h"

#include <dlfcn.h>

#include <filesystem>
#include <map>
#include <mutex>

#include "core/error.h"

// The build tree's plugin folder (core/CMakeLists.txt): tests run from their own folders.
#ifndef PREVIZ_PLUGIN_BUILD_DIR
#define PREVIZ_PLUGIN_BUILD_DIR ""
#endif

namespace fs = std::filesystem;

namespace previz {

namespace {

struct Loaded {
  void* handle = nullptr;
  std::string path;
};

// dlopen's handles are the process's: one registry for it, never unloaded (the plugins' code
// may still run in objects they made, and unloading C++ libraries is rarely safe).
std::mutex& registryMutex() {
  static std::mutex m;
  return m;
}
std::map<std::string, Loaded>& registry() {
  static std::map<std::string, Loaded> loaded;
  return loaded;
}

std::string joined(const std::vector<std::string>& items) {
  std::string s;
  for (const std::string& item : items) s += (s.empty() ? "" : ", ") + item;
  return s;
}

const Loaded& load(const std::string& name, const std::string& purpose) {
  auto& loaded = registry();
  if (auto it = loaded.find(name); it != loaded.end()) return it->second;
  const std::vector<std::string> candidates = pluginCandidates(name);
  std::string path;
  std::error_code ec;
  for (const std::string& c : candidates) {
    if (fs::is_regular_file(c, ec)) {
      path = c;
      break;
    }
  }
  if (path.empty())
    throw Error("the " + name + " plugin (" + purpose + ") is not installed: no " + joined(candidates) +
                " (the build makes it in build/lib; scripts/bundle.sh --plugins copies it beside previz)");
  // RTLD_LOCAL: what the plugin links stays out of the way of what previz links.
  void* handle = ::dlopen(path.c_str(), RTLD_NOW | RTLD_LOCAL);
  if (!handle) {
    const char* why = ::dlerror();
    throw Error("cannot load the " + name + " plugin (" + purpose + "): " + (why ? why : "dlopen failed"),
                fileContext(path));
  }
  return loaded.emplace(name, Loaded{handle, path}).first->second;
}

}  // namespace

std::vector<std::string> pluginCandidates(const std::string& name) {
  const std::string file = name + ".so";
  std::vector<std::string> out;
  auto add = [&](const fs::path& dir) {
    const std::string p = (dir / file).lexically_normal().string();
    for (const std::string& seen : out)
      if (seen == p) return;
    out.push_back(p);
  };
  std::error_code ec;
  const fs::path exe = fs::read_symlink("/proc/self/exe", ec);
  bool bundle = false;
  if (!ec) {
    const fs::path dir = exe.parent_path();
    add(dir);
    add(dir / "lib");
    add(dir.parent_path() / "lib");
    bundle = fs::is_directory(dir / "lib", ec);
  }
  // A bundle is self-contained: a plugin left out of it is missing, whatever the build tree holds.
  const std::string build = PREVIZ_PLUGIN_BUILD_DIR;
  if (!build.empty() && !bundle) add(build);
  return out;
}

void* pluginSymbol(const std::string& name, const char* symbol, const std::string& purpose) {
  std::lock_guard<std::mutex> lock(registryMutex());
  const Loaded& plugin = load(name, purpose);
  ::dlerror();
  void* address = ::dlsym(plugin.handle, symbol);
  if (!address)
    throw Error("the " + name + " plugin (" + purpose + ") has no entry '" + symbol + "': not a previz plugin?",
                fileContext(plugin.path));
  return address;
}

const void* pluginInterface(const std::string& name, const char* entry, int version, const std::string& purpose) {
  using Entry = const void* (*)(int);
  const auto fn = reinterpret_cast<Entry>(pluginSymbol(name, entry, purpose));
  if (const void* api = fn(version)) return api;
  std::string path;
  {
    std::lock_guard<std::mutex> lock(registryMutex());
    path = registry().at(name).path;
  }
  throw Error("the " + name + " plugin (" + purpose + ") is from another previz build (interface version " +
                  std::to_string(version) + " not offered): rebuild or copy the matching one",
              fileContext(path));
}

bool pluginLoaded(const std::string& name) {
  std::lock_guard<std::mutex> lock(registryMutex());
  return registry().count(name) > 0;
}

}  // namespace previz
