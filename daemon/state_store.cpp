#include "daemon/state_store.hpp"

#include <fcntl.h>
#include <sys/stat.h>
#include <unistd.h>

#include <cerrno>
#include <cmath>
#include <ctime>
#include <system_error>

#include "daemon/unique_fd.hpp"

namespace pumptherm::daemon {
namespace {

[[noreturn]] void Throw(int err, const std::string& what) {
  throw std::system_error(err, std::generic_category(), what);
}

std::string StateDirectoryOf(const std::string& path) {
  const auto slash = path.rfind('/');
  if (slash == std::string::npos) return ".";
  if (slash == 0) return "/";
  return path.substr(0, slash);
}

}  // namespace

std::string TemporaryPathOf(const std::string& path) { return path + ".tmp"; }

void WriteFileAtomically(const std::string& path, const std::string& contents, int mode,
                         double test_pause_s) {
  const std::string tmp = TemporaryPathOf(path);
  UniqueFd fd(::open(tmp.c_str(), O_WRONLY | O_CREAT | O_TRUNC | O_CLOEXEC, mode));
  if (!fd.valid()) Throw(errno, "cannot create " + tmp);
  auto fail = [&](const char* step) {
    const int err = errno;
    fd.Reset();
    ::unlink(tmp.c_str());
    Throw(err, std::string(step) + " " + tmp);
  };
  if (::fchmod(fd.get(), static_cast<mode_t>(mode)) < 0) fail("cannot set the mode of");
  auto write_up_to = [&](std::size_t& done, std::size_t end) {
    while (done < end) {
      const ssize_t n = ::write(fd.get(), contents.data() + done, end - done);
      if (n < 0) {
        if (errno == EINTR) continue;
        fail("cannot write");
      }
      done += static_cast<std::size_t>(n);
    }
  };
  std::size_t done = 0;
  if (test_pause_s > 0.0) {
    write_up_to(done, contents.size() / 2);
    timespec pause{};
    pause.tv_sec = static_cast<time_t>(test_pause_s);
    pause.tv_nsec = static_cast<long>(std::fmod(test_pause_s, 1.0) * 1e9);
    while (::nanosleep(&pause, &pause) < 0 && errno == EINTR) {
    }
  }
  write_up_to(done, contents.size());
  if (::fsync(fd.get()) < 0) fail("cannot fsync");
  // close() reports delayed write errors (NFS, quotas); the descriptor is gone either way.
  if (::close(fd.Release()) < 0) {
    const int err = errno;
    ::unlink(tmp.c_str());
    Throw(err, "cannot close " + tmp);
  }
  if (::rename(tmp.c_str(), path.c_str()) < 0) {
    const int err = errno;
    ::unlink(tmp.c_str());
    Throw(err, "cannot rename " + tmp + " to " + path);
  }
  const std::string dir = StateDirectoryOf(path);
  UniqueFd dfd(::open(dir.c_str(), O_RDONLY | O_DIRECTORY | O_CLOEXEC));
  if (!dfd.valid() || ::fsync(dfd.get()) < 0) Throw(errno, "cannot fsync directory " + dir);
}

std::optional<std::string> ReadFileIfExists(const std::string& path) {
  UniqueFd fd(::open(path.c_str(), O_RDONLY | O_CLOEXEC));
  if (!fd.valid()) {
    if (errno == ENOENT) return std::nullopt;
    Throw(errno, "cannot open " + path);
  }
  std::string out;
  char buf[65536];
  for (;;) {
    const ssize_t n = ::read(fd.get(), buf, sizeof buf);
    if (n < 0) {
      if (errno == EINTR) continue;
      Throw(errno, "cannot read " + path);
    }
    if (n == 0) break;
    out.append(buf, static_cast<std::size_t>(n));
  }
  return out;
}

}  // namespace pumptherm::daemon
