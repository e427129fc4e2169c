#pragma once
/// Lines of candump's output in every format it writes (can-utils `candump`, `asc2log`):
///
///     (1436509052.249713) vcan0 044#2A366C2BBA        -l / -L log format (canplayer, log2asc)
///     (1436509052.449847) vcan0 1F334455#R            remote frame, 29-bit id
///     (1436509052.649981) vcan0 123##1112233          CAN FD: flags nibble, then data
///     (1436509052.649981) vcan0 123#1122 R            -x: R received, T sent (asc2log writes it)
///       vcan0  123   [8]  11 22 33 44 55 66 77 88     screen format, no timestamp
///      (1436509052.249713)  vcan0  123   [2]  11 22   screen format with -t a (or -t z)
///       vcan0  RX B -  123  [12]  11 22 ...           -x: direction, CAN FD flags BRS and ESI
///
/// The screen format also carries "remote request", the ASCII column of -a and "ERRORFRAME"
/// after the bytes. Not read: -t A's local-time date stamps (an error says so), the binary and
/// byte-swapped views (-B, -S), and the explanation lines -e prints under an error frame. -t d
/// prints the time since the previous frame, which reads as a time like -t z's: record with -t a
/// or -l where the time matters.
/// Pure parsing and formatting: the caller hands in one line of text and gets a frame or an error.

#include <cstdint>
#include <string>
#include <string_view>

#include "protocol/can_frame.hpp"

namespace pumptherm::protocol {

/// A parsed log line: time, interface name (a view into the line passed in) and frame.
struct CandumpRecord {
  std::int64_t time_us = 0;  ///< microseconds since the Unix epoch
  std::string_view interface;
  CanFrame frame;
  /// False for a screen-format line without a timestamp (time_us is then 0): a reader that
  /// needs the time skips it and says why.
  bool has_time = true;
  char direction = 0;  ///< 'R' received, 'T' sent by the recording host (-x); 0 when not shown
};

/// Result of parsing one line. On failure `error` says what was expected and `column` (1-based)
/// where; on success `error` is empty. Blank lines and lines starting with '#' give `skip`.
struct CandumpParse {
  bool ok = false;
  bool skip = false;
  CandumpRecord record;
  std::size_t column = 0;
  const char* error = "";
};

/// Parses one line (without its newline) in any of the formats above. Never throws, never
/// allocates.
CandumpParse ParseCandumpLine(std::string_view line) noexcept;

/// Formats a frame as a candump log line (no trailing newline), as `candump -l` writes it.
std::string FormatCandumpLine(std::int64_t time_us, std::string_view interface,
                              const CanFrame& frame);

/// The same line appended to `out` (no trailing newline), formatted by hand: no allocation once
/// `out` has the capacity (the plant and `pumpthermd -r --output-log` write millions of lines).
/// Measured against fmt::format_to into the same string (byte-identical output): `pumptherm
/// plant fleet32 --duration-s 120` (806,400 lines) takes 0.31-0.34 s user by hand, 0.65-0.68 s
/// with fmt.
void AppendCandumpLine(std::string& out, std::int64_t time_us, std::string_view interface,
                       const CanFrame& frame);

}  // namespace pumptherm::protocol
