#include "daemon/can_socket.hpp"

#include <fmt/format.h>
#include <linux/can.h>
#include <linux/can/error.h>
#include <linux/can/raw.h>
#include <net/if.h>
#include <sys/ioctl.h>
#include <sys/socket.h>
#include <sys/time.h>

#include <algorithm>
#include <cerrno>
#include <cstdint>
#include <cstring>
#include <fstream>
#include <system_error>

namespace pumptherm::daemon {
namespace {

[[noreturn]] void ThrowErrno(const std::string& what) {
  throw std::system_error(errno, std::generic_category(), what);
}

}  // namespace

std::int64_t ReadRmemMax() {
  std::ifstream f("/proc/sys/net/core/rmem_max");
  std::int64_t v = -1;
  if (!(f >> v)) return -1;
  return v;
}

CanSocket CanSocket::Open(const std::string& name, bool error_frames,
                          std::int64_t rx_buffer_bytes) {
  CanSocket s;
  s.name_ = name;
  s.fd_ = UniqueFd(::socket(PF_CAN, SOCK_RAW | SOCK_NONBLOCK | SOCK_CLOEXEC, CAN_RAW));
  if (!s.fd_.valid()) {
    if (errno == EAFNOSUPPORT) {
      ThrowErrno("interface '" + name +
                 "': cannot open a CAN socket (this kernel has no SocketCAN; "
                 "use -r LOG to process a candump log instead)");
    }
    ThrowErrno("interface '" + name + "': cannot open a CAN socket");
  }
  if (name.size() >= IFNAMSIZ) {
    errno = ENAMETOOLONG;
    ThrowErrno("interface '" + name + "'");
  }
  ifreq ifr{};
  std::memcpy(ifr.ifr_name, name.c_str(), name.size() + 1);
  if (::ioctl(s.fd_.get(), SIOCGIFINDEX, &ifr) < 0) {
    ThrowErrno("interface '" + name + "': cannot find it");
  }
  const int on = 1;
  if (::setsockopt(s.fd_.get(), SOL_SOCKET, SO_TIMESTAMP, &on, sizeof on) < 0) {
    ThrowErrno("interface '" + name + "': SO_TIMESTAMP");
  }
  if (::setsockopt(s.fd_.get(), SOL_SOCKET, SO_RXQ_OVFL, &on, sizeof on) < 0) {
    ThrowErrno("interface '" + name + "': SO_RXQ_OVFL");
  }
  if (::setsockopt(s.fd_.get(), SOL_CAN_RAW, CAN_RAW_FD_FRAMES, &on, sizeof on) < 0) {
    ThrowErrno("interface '" + name + "': CAN_RAW_FD_FRAMES");
  }
  // The receive queue must hold the frames that arrive while the loop is busy elsewhere (a
  // burst, a state save); the default (net.core.rmem_default, 208 KiB) holds about 200 frames.
  // The kernel doubles the value for its bookkeeping and caps an unprivileged request at
  // net.core.rmem_max; SO_RCVBUFFORCE passes the cap with CAP_NET_ADMIN (as candump -r does).
  s.rx_buffer_asked_bytes_ = rx_buffer_bytes;
  if (rx_buffer_bytes > 0) {
    const int asked = static_cast<int>(std::min<std::int64_t>(rx_buffer_bytes, INT32_MAX / 2));
    if (::setsockopt(s.fd_.get(), SOL_SOCKET, SO_RCVBUF, &asked, sizeof asked) < 0) {
      ThrowErrno("interface '" + name + "': SO_RCVBUF");
    }
    int granted = 0;
    socklen_t len = sizeof granted;
    if (::getsockopt(s.fd_.get(), SOL_SOCKET, SO_RCVBUF, &granted, &len) == 0 &&
        granted < 2 * asked) {
      (void)::setsockopt(s.fd_.get(), SOL_SOCKET, SO_RCVBUFFORCE, &asked,
                         sizeof asked);  // EPERM: capped
    }
  }
  int granted = 0;
  socklen_t len = sizeof granted;
  if (::getsockopt(s.fd_.get(), SOL_SOCKET, SO_RCVBUF, &granted, &len) < 0) {
    ThrowErrno("interface '" + name + "': getsockopt SO_RCVBUF");
  }
  s.rx_buffer_granted_bytes_ = granted;
  if (error_frames) {
    const can_err_mask_t mask = CAN_ERR_MASK;
    if (::setsockopt(s.fd_.get(), SOL_CAN_RAW, CAN_RAW_ERR_FILTER, &mask, sizeof mask) < 0) {
      ThrowErrno("interface '" + name + "': CAN_RAW_ERR_FILTER");
    }
  }
  sockaddr_can addr{};
  addr.can_family = AF_CAN;
  addr.can_ifindex = ifr.ifr_ifindex;
  if (::bind(s.fd_.get(), reinterpret_cast<sockaddr*>(&addr), sizeof addr) < 0) {
    ThrowErrno("interface '" + name + "': bind");
  }
  return s;
}

RxStatus CanSocket::Receive(protocol::TimedFrame* out, std::uint32_t* rx_queue_drops_total) {
  canfd_frame raw{};
  iovec iov{&raw, sizeof raw};
  alignas(cmsghdr) char control[CMSG_SPACE(sizeof(timeval)) + CMSG_SPACE(sizeof(std::uint32_t))];
  msghdr msg{};
  msg.msg_iov = &iov;
  msg.msg_iovlen = 1;
  msg.msg_control = control;
  msg.msg_controllen = sizeof control;
  ssize_t n;
  do {
    n = ::recvmsg(fd_.get(), &msg, MSG_DONTWAIT);
  } while (n < 0 && errno == EINTR);
  if (n < 0) {
    last_errno_ = errno;
    switch (errno) {
      case EAGAIN:
        return RxStatus::kEmpty;
      case ENETDOWN:
        return RxStatus::kDown;
      case ENODEV:
      case ENXIO:
        return RxStatus::kGone;
      default:
        return RxStatus::kError;
    }
  }
  if (n != CAN_MTU && n != CANFD_MTU) {
    last_errno_ = EPROTO;
    return RxStatus::kError;
  }
  out->time_us = 0;
  for (cmsghdr* c = CMSG_FIRSTHDR(&msg); c != nullptr; c = CMSG_NXTHDR(&msg, c)) {
    if (c->cmsg_level != SOL_SOCKET) continue;
    if (c->cmsg_type == SO_TIMESTAMP) {
      timeval tv;
      std::memcpy(&tv, CMSG_DATA(c), sizeof tv);
      out->time_us = static_cast<std::int64_t>(tv.tv_sec) * 1000000 + tv.tv_usec;
    } else if (c->cmsg_type == SO_RXQ_OVFL && rx_queue_drops_total != nullptr) {
      std::memcpy(rx_queue_drops_total, CMSG_DATA(c), sizeof(std::uint32_t));
    }
  }
  protocol::CanFrame& f = out->frame;
  f = protocol::CanFrame{};
  f.error = (raw.can_id & CAN_ERR_FLAG) != 0;
  f.extended = !f.error && (raw.can_id & CAN_EFF_FLAG) != 0;
  f.remote = (raw.can_id & CAN_RTR_FLAG) != 0;
  f.id = raw.can_id & (f.extended || f.error ? CAN_EFF_MASK : CAN_SFF_MASK);
  f.fd = n == CANFD_MTU;
  f.fd_flags = f.fd ? raw.flags : 0;
  f.len = raw.len > (f.fd ? CANFD_MAX_DLEN : CAN_MAX_DLEN) ? (f.fd ? CANFD_MAX_DLEN : CAN_MAX_DLEN)
                                                           : raw.len;
  std::memcpy(f.data.data(), raw.data, f.len);
  return RxStatus::kFrame;
}

TxStatus CanSocket::Send(const protocol::CanFrame& f) {
  canfd_frame raw{};
  raw.can_id = f.id | (f.extended ? CAN_EFF_FLAG : 0U) | (f.remote ? CAN_RTR_FLAG : 0U);
  raw.len = f.len;
  raw.flags = f.fd ? f.fd_flags : 0;
  std::memcpy(raw.data, f.data.data(), f.len);
  const std::size_t size = f.fd ? CANFD_MTU : CAN_MTU;
  ssize_t n;
  do {
    n = ::send(fd_.get(), &raw, size, MSG_DONTWAIT);
  } while (n < 0 && errno == EINTR);
  if (n == static_cast<ssize_t>(size)) return TxStatus::kSent;
  last_errno_ = n < 0 ? errno : EIO;
  switch (last_errno_) {
    case ENOBUFS:
    case EAGAIN:
      return TxStatus::kBusy;
    case ENETDOWN:
      return TxStatus::kDown;
    case ENODEV:
    case ENXIO:
      return TxStatus::kGone;
    default:
      return TxStatus::kError;
  }
}

std::string CanSocket::RxBufferReport() const {
  if (rx_buffer_asked_bytes_ <= 0) {
    return fmt::format("{}: receive buffer {} bytes (the kernel's default; rx_buffer_bytes = 0)",
                       name_, rx_buffer_granted_bytes_);
  }
  if (!rx_buffer_capped()) {
    return fmt::format("{}: receive buffer {} bytes (rx_buffer_bytes = {}, doubled by the kernel)",
                       name_, rx_buffer_granted_bytes_, rx_buffer_asked_bytes_);
  }
  const std::int64_t rmem_max = ReadRmemMax();
  return fmt::format(
      "{}: receive buffer capped at {} bytes (rx_buffer_bytes = {} asks for {}): an unprivileged "
      "socket "
      "gets at most net.core.rmem_max ({}) x 2; raise the cap with a sysctl.d drop-in, e.g. "
      "/etc/sysctl.d/60-pumptherm.conf: net.core.rmem_max = {} (docs/daemon.md, \"Receive "
      "buffer\")",
      name_, rx_buffer_granted_bytes_, rx_buffer_asked_bytes_, 2 * rx_buffer_asked_bytes_,
      rmem_max >= 0 ? fmt::format("{}", rmem_max) : std::string("unreadable"),
      rx_buffer_asked_bytes_);
}

bool CanSocket::InterfaceUp() const {
  if (!fd_.valid()) return false;
  ifreq ifr{};
  std::memcpy(ifr.ifr_name, name_.c_str(), name_.size() + 1);
  if (::ioctl(fd_.get(), SIOCGIFFLAGS, &ifr) < 0) return false;
  return (ifr.ifr_flags & IFF_UP) != 0 && (ifr.ifr_flags & IFF_RUNNING) != 0;
}

}  // namespace pumptherm::daemon
