#include "daemon/frame_counter.hpp"

#include <fmt/format.h>
#include <linux/can/error.h>

#include <cmath>
#include <limits>

namespace pumptherm::daemon {
namespace {

/// The count key as one integer: interface index, extended flag, CAN ID.
std::uint64_t PackedKey(std::size_t iface, bool extended, std::uint32_t id) {
  return (static_cast<std::uint64_t>(iface) << 33) | (static_cast<std::uint64_t>(extended) << 32) |
         id;
}

}  // namespace

BusState NextBusState(BusState state, const protocol::CanFrame& frame) {
  if (!frame.error) return state;
  const std::uint32_t cls = frame.id;
  if ((cls & CAN_ERR_BUSOFF) != 0U) return BusState::kBusOff;
  if ((cls & CAN_ERR_RESTARTED) != 0U) state = BusState::kErrorActive;
  if ((cls & CAN_ERR_CRTL) != 0U && frame.len >= 2) {
    const std::uint8_t crtl = frame.data[1];
    if ((crtl & (CAN_ERR_CRTL_RX_PASSIVE | CAN_ERR_CRTL_TX_PASSIVE)) != 0U)
      return BusState::kErrorPassive;
    if ((crtl & (CAN_ERR_CRTL_RX_WARNING | CAN_ERR_CRTL_TX_WARNING)) != 0U)
      return BusState::kErrorWarning;
    if ((crtl & CAN_ERR_CRTL_ACTIVE) != 0U) return BusState::kErrorActive;
  }
  if (state == BusState::kUnknown) return BusState::kErrorActive;  // it talks: not bus-off
  return state;
}

std::size_t FrameCounter::Interface(std::string_view name) {
  for (std::size_t i = 0; i < interfaces_.size(); ++i) {
    if (interfaces_[i].name == name) return i;
  }
  interfaces_.push_back(InterfaceCounters{.name = std::string(name)});
  standard_counts_.resize(interfaces_.size() * kStandardIds, 0);
  return interfaces_.size() - 1;
}

void FrameCounter::OnFrame(std::size_t iface, const protocol::TimedFrame& timed) {
  InterfaceCounters& c = interfaces_[iface];
  if (timed.frame.error) {
    ++c.rx_error_frames;
    c.bus_state = NextBusState(c.bus_state, timed.frame);
    return;
  }
  ++c.rx_frames;
  ++total_rx_;
  if (!timed.frame.extended && timed.frame.id < kStandardIds) {
    std::uint64_t& n = standard_counts_[iface * kStandardIds + timed.frame.id];
    distinct_ids_ += n == 0;
    ++n;
    return;
  }
  std::uint64_t& n = extended_counts_[PackedKey(iface, timed.frame.extended, timed.frame.id)];
  distinct_ids_ += n == 0;
  ++n;
}

std::map<FrameCounter::CountKey, std::uint64_t> FrameCounter::counts() const {
  std::map<CountKey, std::uint64_t> sorted;
  for (std::size_t k = 0; k < standard_counts_.size(); ++k) {
    if (standard_counts_[k] == 0) continue;
    sorted.emplace(CountKey{k / kStandardIds, false, static_cast<std::uint32_t>(k % kStandardIds)},
                   standard_counts_[k]);
  }
  for (const auto& [key, n] : extended_counts_) {
    sorted.emplace(CountKey{static_cast<std::size_t>(key >> 33), ((key >> 32) & 1U) != 0,
                            static_cast<std::uint32_t>(key & 0xFFFFFFFFU)},
                   n);
  }
  return sorted;
}

std::optional<protocol::CanFrame> FrameCounter::HeartbeatDue(std::int64_t now_us) {
  if (config_.heartbeat_period_s <= 0.0) return std::nullopt;
  if (start_us_ < 0) {
    start_us_ = now_us;
    next_heartbeat_us_ = now_us;
  }
  if (now_us < next_heartbeat_us_) return std::nullopt;
  const auto period_us = static_cast<std::int64_t>(std::llround(config_.heartbeat_period_s * 1e6));
  next_heartbeat_us_ += period_us;
  // After a stall longer than a period, skip the missed beats instead of bursting them.
  if (next_heartbeat_us_ <= now_us) next_heartbeat_us_ = now_us + period_us;
  protocol::CanFrame f;
  f.id = config_.heartbeat_id;
  f.len = 8;
  const auto uptime_s = static_cast<std::uint32_t>((now_us - start_us_) / 1000000);
  const auto rx = static_cast<std::uint32_t>(total_rx_);
  for (int k = 0; k < 4; ++k) {
    f.data[k] = static_cast<std::uint8_t>(uptime_s >> (8 * k));
    f.data[4 + k] = static_cast<std::uint8_t>(rx >> (8 * k));
  }
  return f;
}

std::int64_t FrameCounter::NextHeartbeatUs() const {
  if (config_.heartbeat_period_s <= 0.0) return std::numeric_limits<std::int64_t>::max();
  return next_heartbeat_us_ < 0 ? 0 : next_heartbeat_us_;
}

std::string FrameCounter::StatusLine() const {
  std::uint64_t drops = 0;
  std::uint64_t tx = 0;
  std::uint64_t tx_dropped = 0;
  std::string states;
  for (const auto& c : interfaces_) {
    drops += c.rx_queue_drops;
    tx += c.tx_frames;
    tx_dropped += c.tx_dropped;
    states += fmt::format(" {}:{}", c.name, c.up ? "up" : "DOWN");
  }
  return fmt::format("rx {} frames, {} IDs, {} rx drops; tx {} frames, {} tx dropped;{}", total_rx_,
                     distinct_ids_, drops, tx, tx_dropped, states);
}

std::string FrameCounter::CountTable() const {
  std::string out = fmt::format("{:<16} {:>8} {:>12}\n", "interface", "can_id", "frames");
  for (const auto& [key, n] : counts()) {
    const auto& [iface, extended, id] = key;
    out += fmt::format("{:<16} {:>8} {:>12}\n", interfaces_[iface].name,
                       extended ? fmt::format("{:08X}", id) : fmt::format("{:03X}", id), n);
  }
  return out;
}

}  // namespace pumptherm::daemon
