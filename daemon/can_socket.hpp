#pragma once
/// A SocketCAN CAN_RAW socket bound to one interface: non-blocking, kernel receive timestamps
/// (SO_TIMESTAMP), receive-queue drop counting (SO_RXQ_OVFL), CAN FD frames accepted, and a
/// receive buffer of the configured size (SO_RCVBUF; what the kernel granted is kept).
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
  kFrame,  ///< a frame was stored
  kEmpty,  ///< nothing to read now (EAGAIN)
  kDown,   ///< the interface is down (ENETDOWN); the socket stays usable when it comes back up
  kGone,   ///< the interface was removed (ENODEV); the socket must be reopened
  kError,  ///< any other error; errno is in `last_errno()`
};

enum class TxStatus {
  kSent,
  kBusy,  ///< transmit queue full (ENOBUFS/EAGAIN): frame dropped, counted
  kDown,  ///< interface down (ENETDOWN): frame dropped
  kGone,  ///< interface removed (ENODEV/ENXIO)
  kError,
};

class CanSocket {
 public:
  /// Opens and binds a socket on interface `name`. With `error_frames` the socket also receives
  /// error frames (all error classes). `rx_buffer_bytes` > 0 is asked for as SO_RCVBUF (the
  /// kernel doubles it and caps an unprivileged request at net.core.rmem_max; when capped,
  /// SO_RCVBUFFORCE is tried, which needs CAP_NET_ADMIN); 0 keeps the kernel's default. What was
  /// granted is in rx_buffer_granted_bytes(). Throws std::system_error when the kernel has no
  /// SocketCAN, the interface does not exist, or a socket option cannot be set.
  static CanSocket Open(const std::string& name, bool error_frames,
                        std::int64_t rx_buffer_bytes = 0);

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

  /// The receive buffer asked for at Open (bytes; 0 = the kernel's default).
  std::int64_t rx_buffer_asked_bytes() const { return rx_buffer_asked_bytes_; }
  /// The receive buffer the kernel granted (getsockopt SO_RCVBUF, bytes: its doubled value).
  std::int64_t rx_buffer_granted_bytes() const { return rx_buffer_granted_bytes_; }
  /// Whether the kernel granted less than it grants an uncapped request (twice the asked size).
  bool rx_buffer_capped() const {
    return rx_buffer_asked_bytes_ > 0 && rx_buffer_granted_bytes_ < 2 * rx_buffer_asked_bytes_;
  }
  /// One line for the log about the receive buffer: asked, granted, and when the kernel capped
  /// it (granted below twice the asked size) why and how to raise the cap.
  std::string RxBufferReport() const;

 private:
  UniqueFd fd_;
  std::string name_;
  int last_errno_ = 0;
  std::int64_t rx_buffer_asked_bytes_ = 0;
  std::int64_t rx_buffer_granted_bytes_ = 0;
};

/// net.core.rmem_max (/proc/sys/net/core/rmem_max), bytes; -1 when it cannot be read.
std::int64_t ReadRmemMax();

}  // namespace pumptherm::daemon
