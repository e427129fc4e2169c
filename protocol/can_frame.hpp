#pragma once
/// A CAN or CAN FD frame as the pure libraries see it: no kernel headers, no sockets.

#include <array>
#include <cstdint>

namespace pumptherm::protocol {

/// Longest CAN FD payload in bytes.
inline constexpr std::size_t kMaxFrameBytes = 64;

/// One frame. `id` holds 11 bits, or 29 bits when `extended` is set (no flag bits in it).
struct CanFrame {
  std::uint32_t id = 0;
  bool extended = false;
  bool fd = false;            ///< CAN FD frame (payload up to 64 bytes)
  bool remote = false;        ///< remote transmission request (classic CAN only)
  bool error = false;         ///< error frame (id holds the error class bits)
  std::uint8_t fd_flags = 0;  ///< CAN FD flags nibble as candump writes it (BRS = 1, ESI = 2)
  std::uint8_t len = 0;       ///< payload length in bytes
  std::array<std::uint8_t, kMaxFrameBytes> data{};
};

/// A frame with the time it was received (kernel timestamp or log time) and its interface.
struct TimedFrame {
  std::int64_t time_us = 0;  ///< receive time, microseconds since the Unix epoch
  CanFrame frame;
};

}  // namespace pumptherm::protocol
