#include "daemon/can_socket.hpp"

#include <linux/can.h>
#include <linux/can/error.h>
#include <linux/can/raw.h>
#include <net/if.h>
#include <sys/ioctl.h>
#include <sys/socket.h>
#include <sys/time.h>

#include <cerrno>
#include <cstring>
#include <system_error>

namespace pumptherm::daemon {
namespace {

[[noreturn]] void ThrowErrno(const std::string& what) {
  throw std::system_error(errno, std::generic_category(), what);
}

}  // namespace

CanSocket CanSocket::Open(const std::string& name, bool error_frames) {
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
      case EAGAIN: return RxStatus::kEmpty;
      case ENETDOWN: return RxStatus::kDown;
      case ENODEV: case ENXIO: return RxStatus::kGone;
      default: return RxStatus::kError;
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
    case ENOBUFS: case EAGAIN: return TxStatus::kBusy;
    case ENETDOWN: return TxStatus::kDown;
    case ENODEV: case ENXIO: return TxStatus::kGone;
    default: return TxStatus::kError;
  }
}

bool CanSocket::InterfaceUp() const {
  if (!fd_.valid()) return false;
  ifreq ifr{};
  std::memcpy(ifr.ifr_name, name_.c_str(), name_.size() + 1);
  if (::ioctl(fd_.get(), SIOCGIFFLAGS, &ifr) < 0) return false;
  return (ifr.ifr_flags & IFF_UP) != 0 && (ifr.ifr_flags & IFF_RUNNING) != 0;
}

}  // namespace pumptherm::daemon
