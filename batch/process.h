#pragma once
// Child processes for the batch: start a command (argv, no shell) with its stdout and stderr
// going to files, and wait for it. POSIX fork/exec; errors name the program.
#include <sys/types.h>

#include <filesystem>
#include <map>
#include <string>
#include <vector>

namespace previz::batch {

struct ProcessSpec {
  std::vector<std::string> argv;
  std::filesystem::path stdout_path;             // "" = inherit
  std::filesystem::path stderr_path;             // "" = inherit
  std::map<std::string, std::string> env;        // set in the child on top of ours
};

// Starts the process; throws Error naming argv[0] when it cannot be started.
pid_t startProcess(const ProcessSpec& spec);
// Exit status of a finished child: its code, or 128 + signal when killed.
int exitStatus(int wait_status);
// Runs to the end and returns exitStatus().
int runProcess(const ProcessSpec& spec);

// Runs argv with stdout captured (stderr inherited unless quiet); returns the exit status.
int captureOutput(const std::vector<std::string>& argv, std::string& out, bool quiet_stderr = true);

}  // namespace previz::batch
