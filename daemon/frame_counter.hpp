#pragma once
/// Frame and interface counters and the heartbeat, independent of where frames come from (live
/// sockets or a candump log) and of the clock (time enters as an argument): frames per
/// interface and CAN ID, drops, interface states, and the gateway heartbeat frame.

#include <cstdint>
#include <map>
#include <optional>
#include <string>
#include <string_view>
#include <tuple>
#include <unordered_map>
#include <vector>

#include "daemon/config.hpp"
#include "protocol/can_frame.hpp"

namespace pumptherm::daemon {

/// Controller state of a CAN interface as its error frames tell it (linux/can/error.h); only
/// known when the interface's error frames are requested (config `error_frames = true`).
enum class BusState : std::uint8_t {
  kUnknown,
  kErrorActive,
  kErrorWarning,
  kErrorPassive,
  kBusOff
};

/// The bus state after error frame `frame` (id: the error class bits, data: the details of
/// linux/can/error.h), starting from `state`: bus-off (CAN_ERR_BUSOFF), passive or warning
/// (CAN_ERR_CRTL with the RX/TX passive or warning bits in data[1]), back to active
/// (CAN_ERR_CRTL_ACTIVE, or CAN_ERR_RESTARTED after a bus-off). Other error classes (protocol
/// violations, lost arbitration, missing ACK) leave the state as it was.
BusState NextBusState(BusState state, const protocol::CanFrame& frame);

/// Counters of one interface.
struct InterfaceCounters {
  std::string name;
  std::uint64_t rx_frames = 0;
  std::uint64_t rx_queue_drops = 0;  ///< frames the kernel dropped (SO_RXQ_OVFL)
  std::uint64_t rx_error_frames = 0;
  std::uint64_t tx_frames = 0;
  std::uint64_t tx_dropped = 0;  ///< ENOBUFS/EAGAIN/ENETDOWN on send: counted, not fatal
  std::uint64_t reopens = 0;     ///< times the socket was reopened after the interface vanished
  std::uint64_t rx_second_sender = 0;       ///< frames another sender must have sent (Gateway)
  BusState bus_state = BusState::kUnknown;  ///< from error frames; see NextBusState
  bool up = true;
};

class FrameCounter {
 public:
  explicit FrameCounter(GatewayConfig config) : config_(std::move(config)) {}

  /// Index of the interface called `name`, registered on first use.
  std::size_t Interface(std::string_view name);

  /// Counts one received frame on interface `iface` (from Interface()).
  void OnFrame(std::size_t iface, const protocol::TimedFrame& frame);

  /// The heartbeat frame to send at monotonic time `now_us`, if one is due. The first is due at
  /// the first call; then every heartbeat_period_s without drift.
  /// Layout (8 bytes, little endian): uptime in s (u32), frames received in all (u32, wraps).
  std::optional<protocol::CanFrame> HeartbeatDue(std::int64_t now_us);

  /// Next monotonic time a heartbeat is due (INT64_MAX when disabled).
  std::int64_t NextHeartbeatUs() const;

  InterfaceCounters& counters(std::size_t iface) { return interfaces_[iface]; }
  const std::vector<InterfaceCounters>& interfaces() const { return interfaces_; }

  /// Frames per (interface index, extended, CAN ID).
  using CountKey = std::tuple<std::size_t, bool, std::uint32_t>;
  /// Sorted by key; made on each call (the count itself is a hash lookup per frame).
  std::map<CountKey, std::uint64_t> counts() const;
  std::uint64_t total_rx() const { return total_rx_; }

  /// One line for systemd's STATUS= and the journal: totals, drops and interface states.
  std::string StatusLine() const;

  /// The per-ID count table (fixed-width columns, one row per interface and CAN ID).
  std::string CountTable() const;

 private:
  GatewayConfig config_;
  std::vector<InterfaceCounters> interfaces_;
  /// Frames per 11-bit ID, kStandardIds per interface (an index, no hashing: the common case),
  /// and per PackedKey(iface, extended, id) for 29-bit IDs.
  static constexpr std::size_t kStandardIds = 2048;
  std::vector<std::uint64_t> standard_counts_;
  std::unordered_map<std::uint64_t, std::uint64_t> extended_counts_;
  std::size_t distinct_ids_ = 0;
  std::uint64_t total_rx_ = 0;
  std::int64_t start_us_ = -1;
  std::int64_t next_heartbeat_us_ = -1;
};

}  // namespace pumptherm::daemon
