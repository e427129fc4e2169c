#pragma once
/// The daemon's LCM side: publishes encoded messages and receives alarm-clear commands.
/// LCM 1.3 (no lambda subscriptions): a handler method; its file descriptor sits in the
/// daemon's own epoll loop (getFileno), and Handle() is called when it is readable.

#include <cstdint>
#include <functional>
#include <memory>
#include <optional>
#include <string>
#include <vector>

namespace lcm {
class LCM;
}

namespace pumptherm {
class alarm_clear_t;
}

namespace pumptherm::daemon {

class LcmBridge {
 public:
  /// Called with each message on <prefix>/<pump>/ALARM_CLEAR; `m` is nullptr when its bytes
  /// do not decode as alarm_clear_t (another type, an older layout), so that those are counted.
  using ClearHandler =
      std::function<void(const std::string& channel, const pumptherm::alarm_clear_t* m)>;

  /// Connects to `url` (e.g. "udpm://239.255.76.67:7667?ttl=0", or "memq://" in tests) and
  /// subscribes to <prefix>/<pump>/ALARM_CLEAR. Throws std::runtime_error when LCM cannot start.
  LcmBridge(const std::string& url, const std::string& prefix, ClearHandler on_clear);
  ~LcmBridge();
  LcmBridge(const LcmBridge&) = delete;
  LcmBridge& operator=(const LcmBridge&) = delete;

  /// The descriptor to poll for incoming messages.
  int fd();
  /// Dispatches whatever is waiting, without blocking.
  void Handle();
  /// Publishes raw encoded bytes; false when LCM refused (counted by the caller), with the
  /// reason in last_errno() (e.g. ENETUNREACH when the multicast route is gone). LCM 1.3 reports
  /// a failure only for messages that fit one datagram (1400 bytes with the channel name): a
  /// fragmented one counts as sent whatever happened; ours are far smaller.
  bool Publish(const std::string& channel, const std::vector<std::uint8_t>& bytes);
  /// errno of the last failed Publish (0 when LCM gave none).
  int last_errno() const { return last_errno_; }

  /// Restricts what LCM receives to this host and the interfaces named (lcm_boundary.hpp):
  /// returns what was done, in words, for the journal. A URL of another provider than udpm://
  /// (memq:// in tests) has no socket to restrict: says so. An interface that does not exist is
  /// left out, with a warning in the text. Throws std::runtime_error when LCM's receiving socket
  /// cannot be found or filtered (the daemon then does not start: it never listens unguarded).
  std::string RestrictToThisHost(const std::vector<std::string>& interfaces);
  /// Datagrams the kernel dropped on LCM's receiving socket (from outside the boundary, or a
  /// full buffer); nullopt before RestrictToThisHost or without a udpm socket.
  std::optional<std::uint64_t> ReceiveDrops() const;

 private:
  struct Impl;
  std::unique_ptr<Impl> impl_;
  int last_errno_ = 0;
  std::string url_;
  int receive_fd_ = -1;  // LCM's own receiving socket (LCM owns and closes it)
};

}  // namespace pumptherm::daemon
