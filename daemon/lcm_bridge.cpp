#include "daemon/lcm_bridge.hpp"

#include <fmt/format.h>
#include <net/if.h>

#include <cerrno>
#include <lcm/lcm-cpp.hpp>
#include <stdexcept>
#include <system_error>

#include "daemon/lcm_boundary.hpp"
#include "protocol/lcm/channels.hpp"
#include "pumptherm/alarm_clear_t.hpp"

namespace pumptherm::daemon {
namespace {

constexpr int kClearQueueCapacity = 4096;

}  // namespace

struct LcmBridge::Impl {
  lcm::LCM lcm;
  ClearHandler on_clear;
  explicit Impl(const std::string& url) : lcm(url) {}
  pumptherm::alarm_clear_t message;  // decoded in place
  // Raw bytes, decoded here: LCM's typed handler drops a message that does not decode
  // without telling anyone, and a refused clear must be counted.
  void OnClear(const lcm::ReceiveBuffer* rbuf, const std::string& channel) {
    if (!on_clear) return;
    const int size = static_cast<int>(rbuf->data_size);
    const bool ok = message.decode(rbuf->data, 0, size) == size;
    on_clear(channel, ok ? &message : nullptr);
  }
};

LcmBridge::LcmBridge(const std::string& url, const std::string& prefix, ClearHandler on_clear)
    : impl_(std::make_unique<Impl>(url)), url_(url) {
  if (!impl_->lcm.good()) throw std::runtime_error("LCM: cannot start with URL '" + url + "'");
  impl_->on_clear = std::move(on_clear);
  lcm::Subscription* sub = impl_->lcm.subscribe(
      lcm_channels::AllPumpsPattern(prefix, lcm_channels::PumpChannel::kAlarmClear), &Impl::OnClear,
      impl_.get());
  // LCM queues 30 messages per subscription and drops the rest: in a flood of forged clears a
  // pause of the loop of 1.5 ms would drop a legitimate one. This holds 200 ms of 20 000 per s
  // (each refused in about 1 us; docs/threat-model.md).
  sub->setQueueCapacity(kClearQueueCapacity);
}

LcmBridge::~LcmBridge() = default;

int LcmBridge::fd() { return impl_->lcm.getFileno(); }

void LcmBridge::Handle() {
  // handleTimeout(0) returns at once when nothing is waiting (0) and > 0 after one message.
  for (int k = 0; k < 64 && impl_->lcm.handleTimeout(0) > 0; ++k) {
  }
}

bool LcmBridge::Publish(const std::string& channel, const std::vector<std::uint8_t>& bytes) {
  errno = 0;
  if (impl_->lcm.publish(channel, bytes.data(), static_cast<unsigned int>(bytes.size())) == 0)
    return true;
  last_errno_ = errno;  // sendmsg's, when that is what failed
  return false;
}

std::string LcmBridge::RestrictToThisHost(const std::vector<std::string>& interfaces) {
  const std::optional<std::uint16_t> port = UdpmPort(url_);
  if (!port) {
    return fmt::format("LCM URL '{}' is not udpm://: no receiving socket of the daemon's to limit",
                       url_);
  }
  // The receiving socket exists once something is subscribed (the constructor did).
  const std::optional<int> fd = FindUdpSocketBoundTo(*port);
  if (!fd) {
    throw std::runtime_error(fmt::format(
        "LCM: its receiving socket (UDP port {}) was not found, so it cannot be limited "
        "to this host; not starting",
        *port));
  }
  std::vector<int> indexes;
  std::string taken, missing;
  for (const std::string& name : interfaces) {
    const unsigned index = ::if_nametoindex(name.c_str());
    if (index == 0) {
      missing += (missing.empty() ? "" : ", ") + name;
      continue;
    }
    indexes.push_back(static_cast<int>(index));
    taken += ", " + name;
  }
  const unsigned lo = ::if_nametoindex("lo");
  try {
    AttachFilter(*fd, HostOnlyFilter(lo == 0 ? 1 : static_cast<int>(lo), indexes));
  } catch (const std::system_error& e) {
    throw std::runtime_error(fmt::format("LCM: {}; not starting unguarded", e.what()));
  }
  receive_fd_ = *fd;
  std::string text = fmt::format("LCM receives from this host{} only (port {})", taken, *port);
  if (!missing.empty())
    text += fmt::format("; lcm.receive_interfaces not found, left out: {}", missing);
  return text;
}

std::optional<std::uint64_t> LcmBridge::ReceiveDrops() const {
  if (receive_fd_ < 0) return std::nullopt;
  return SocketDrops(receive_fd_);
}

}  // namespace pumptherm::daemon
