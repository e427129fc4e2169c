// Helpers the gateway's files share (daemon/gateway*.cpp); not part of the gateway's interface.
#pragma once

#include <cstdint>
#include <vector>

#include "daemon/pump.hpp"

namespace pumptherm::daemon::gateway_detail {

/// Whether the alarm state is worth sending: with an estimate, with a latched trip (also while
/// the filter has none), or with any condition raised (a pump never heard from is stale).
inline bool AlarmKnown(const PumpSnapshot& s) {
  return s.initialised || s.alarm.trip_latched || s.alarm.level != estimators::AlarmLevel::kNone;
}

/// The key of a route: interface, frame format and CAN ID.
constexpr std::uint64_t RouteKey(std::size_t iface, bool extended, std::uint32_t id) {
  return (static_cast<std::uint64_t>(iface) << 33) | (static_cast<std::uint64_t>(extended) << 32) |
         id;
}

/// An LCM message's bytes.
template <typename Message>
std::vector<std::uint8_t> Encode(const Message& m) {
  std::vector<std::uint8_t> bytes(static_cast<std::size_t>(m.getEncodedSize()));
  m.encode(bytes.data(), 0, static_cast<int>(bytes.size()));
  return bytes;
}

/// Encodes `m` into `bytes` (resized; no allocation once it has held a message this large).
template <typename Message>
void EncodeInto(const Message& m, std::vector<std::uint8_t>& bytes) {
  bytes.resize(static_cast<std::size_t>(m.getEncodedSize()));
  m.encode(bytes.data(), 0, static_cast<int>(bytes.size()));
}

}  // namespace pumptherm::daemon::gateway_detail
