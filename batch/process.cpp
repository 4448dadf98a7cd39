// Child processes (see process.h).
#include "batch/process.h"

#include <fcntl.h>
#include <sys/wait.h>
#include <unistd.h>

#include <cerrno>
#include <cstring>

#include "core/error.h"

namespace previz::batch {
namespace {

// Everything the child needs is prepared before fork(): after it only async-signal-safe calls.
struct Prepared {
  std::vector<std::string> storage;
  std::vector<char*> argv;
  std::vector<std::pair<std::string, std::string>> env;
};

[[noreturn]] void childExec(const Prepared& p, int out_fd, int err_fd) {
  if (out_fd >= 0) dup2(out_fd, 1);
  if (err_fd >= 0) dup2(err_fd, 2);
  for (const auto& [k, v] : p.env) setenv(k.c_str(), v.c_str(), 1);
  execvp(p.argv[0], p.argv.data());
  const char msg[] = "previz batch: exec failed\n";
  (void)!write(2, msg, sizeof(msg) - 1);
  _exit(127);
}

int openOutput(const std::filesystem::path& path) {
  if (path.empty()) return -1;
  std::error_code ec;
  std::filesystem::create_directories(path.parent_path(), ec);
  const int fd = ::open(path.c_str(), O_WRONLY | O_CREAT | O_TRUNC | O_CLOEXEC, 0644);
  if (fd < 0) throw Error(std::string("cannot open for writing: ") + std::strerror(errno), fileContext(path.string()));
  return fd;
}

}  // namespace

pid_t startProcess(const ProcessSpec& spec) {
  if (spec.argv.empty()) throw Error("empty command");
  Prepared p;
  p.storage = spec.argv;
  for (std::string& s : p.storage) p.argv.push_back(s.data());
  p.argv.push_back(nullptr);
  p.env.assign(spec.env.begin(), spec.env.end());
  const int out_fd = openOutput(spec.stdout_path);
  const int err_fd = openOutput(spec.stderr_path);
  const pid_t pid = fork();
  if (pid == 0) childExec(p, out_fd, err_fd);
  const int fork_errno = errno;
  if (out_fd >= 0) ::close(out_fd);
  if (err_fd >= 0) ::close(err_fd);
  if (pid < 0) throw Error(std::string("cannot start: ") + std::strerror(fork_errno), fileContext(spec.argv[0]));
  return pid;
}

int exitStatus(int wait_status) {
  if (WIFEXITED(wait_status)) return WEXITSTATUS(wait_status);
  if (WIFSIGNALED(wait_status)) return 128 + WTERMSIG(wait_status);
  return 255;
}

int runProcess(const ProcessSpec& spec) {
  const pid_t pid = startProcess(spec);
  int status = 0;
  while (waitpid(pid, &status, 0) < 0) {
    if (errno != EINTR) throw Error("waitpid failed", fileContext(spec.argv[0]));
  }
  return exitStatus(status);
}

int captureOutput(const std::vector<std::string>& argv, std::string& out, bool quiet_stderr) {
  if (argv.empty()) throw Error("empty command");
  int fds[2];
  if (pipe2(fds, O_CLOEXEC) != 0) throw Error("pipe failed", fileContext(argv[0]));
  Prepared p;
  p.storage = argv;
  for (std::string& s : p.storage) p.argv.push_back(s.data());
  p.argv.push_back(nullptr);
  const int err_fd = quiet_stderr ? ::open("/dev/null", O_WRONLY | O_CLOEXEC) : -1;
  const pid_t pid = fork();
  if (pid == 0) childExec(p, fds[1], err_fd);
  ::close(fds[1]);
  if (err_fd >= 0) ::close(err_fd);
  if (pid < 0) {
    ::close(fds[0]);
    throw Error("cannot start", fileContext(argv[0]));
  }
  out.clear();
  char buffer[4096];
  for (;;) {
    const ssize_t n = ::read(fds[0], buffer, sizeof(buffer));
    if (n > 0) {
      out.append(buffer, static_cast<size_t>(n));
    } else if (n == 0 || errno != EINTR) {
      break;
    }
  }
  ::close(fds[0]);
  int status = 0;
  while (waitpid(pid, &status, 0) < 0 && errno == EINTR) {
  }
  return exitStatus(status);
}

}  // namespace previz::batch
