#pragma once
/// A SocketCAN CAN_RAW socket bound to one interface: non-blocking, kernel receive timestamps
/// (SO_TIMESTAMP), receive-queue drop counting (SO_RXQ_OVFL), CAN FD frames accepted.
///
/// Open() throws std::system_error (with errno and what was being done). Receive() and Send()
/// never throw and never block: expected events (no frame, interface down or gone, queue full)
/// are returned as status values for the loop to count.

#include <cstdint>
#include <string>

#include "daemon/unique_fd.hpp"
#include "protocol/can_frame.hpp"

namespace pumptherm::daemon {

enum class RxStatus {
  kFrame,   ///< a frame was stored
  kEmpty,   ///< nothing to read now (EAGAIN)
  kDown,    ///< the interface is down (ENETDOWN); the socket stays usable when it comes back up
  kGone,    ///< the interface was removed (ENODEV); the socket must be reopened
  kError,   ///< any other error; errno is in `last_errno()`
};

enum class TxStatus {
  kSent,
  kBusy,    ///< transmit queue full (ENOBUFS/EAGAIN): frame dropped, counted
  kDown,    ///< interface down (ENETDOWN): frame dropped
  kGone,    ///< interface removed (ENODEV/ENXIO)
  kError,
};

class CanSocket {
 public:
  /// Opens and binds a socket on interface `name`. With `error_frames` the socket also receives
  /// error frames (all error classes). Throws std::system_error when the kernel has no SocketCAN,
  /// the interface does not exist, or a socket option cannot be set.
  static CanSocket Open(const std::string& name, bool error_frames);

  CanSocket() = default;
  CanSocket(CanSocket&&) noexcept = default;
  CanSocket& operator=(CanSocket&&) noexcept = default;

  int fd() const { return fd_.get(); }
  bool is_open() const { return fd_.valid(); }
  const std::string& name() const { return name_; }
  void Close() { fd_.Reset(); }

  /// Reads one frame if one is waiting. `out->time_us` is the kernel receive time (Unix epoch).
  /// `rx_queue_drops_total` receives the kernel's cumulative drop counter when it is reported.
  RxStatus Receive(protocol::TimedFrame* out, std::uint32_t* rx_queue_drops_total);

  /// Queues one frame for sending. Timeout: none; never blocks.
  TxStatus Send(const protocol::CanFrame& frame);

  /// Whether the interface is administratively up and running (SIOCGIFFLAGS). False when it is
  /// down or no longer exists.
  bool InterfaceUp() const;

  int last_errno() const { return last_errno_; }

 private:
  UniqueFd fd_;
  std::string name_;
  int last_errno_ = 0;
};

}  // namespace pumptherm::daemon
