#pragma once
/// Move-only owner of a file descriptor: every descriptor lives in one from the line that
/// creates it, so no path (throw, early return) leaks it.

#include <unistd.h>

#include <utility>

namespace pumptherm::daemon {

class UniqueFd {
 public:
  UniqueFd() = default;
  explicit UniqueFd(int fd) noexcept : fd_(fd) {}
  ~UniqueFd() { Reset(); }
  UniqueFd(UniqueFd&& other) noexcept : fd_(std::exchange(other.fd_, -1)) {}
  UniqueFd& operator=(UniqueFd&& other) noexcept {
    if (this != &other) {
      Reset();
      fd_ = std::exchange(other.fd_, -1);
    }
    return *this;
  }
  UniqueFd(const UniqueFd&) = delete;
  UniqueFd& operator=(const UniqueFd&) = delete;

  int get() const noexcept { return fd_; }
  bool valid() const noexcept { return fd_ >= 0; }
  /// Gives up ownership without closing (e.g. to close it once and check the result).
  int Release() noexcept { return std::exchange(fd_, -1); }
  /// Closes the descriptor (if any); close errors are ignored, as nothing can be done then.
  void Reset() noexcept {
    if (fd_ >= 0) ::close(fd_);
    fd_ = -1;
  }

 private:
  int fd_ = -1;
};

}  // namespace pumptherm::daemon
