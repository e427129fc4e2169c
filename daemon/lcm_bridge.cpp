#include "daemon/lcm_bridge.hpp"

#include <cerrno>
#include <lcm/lcm-cpp.hpp>
#include <stdexcept>

#include "protocol/lcm/channels.hpp"
#include "pumptherm/alarm_clear_t.hpp"

namespace pumptherm::daemon {

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
    : impl_(std::make_unique<Impl>(url)) {
  if (!impl_->lcm.good()) throw std::runtime_error("LCM: cannot start with URL '" + url + "'");
  impl_->on_clear = std::move(on_clear);
  impl_->lcm.subscribe(
      lcm_channels::AllPumpsPattern(prefix, lcm_channels::PumpChannel::kAlarmClear), &Impl::OnClear,
      impl_.get());
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

}  // namespace pumptherm::daemon
