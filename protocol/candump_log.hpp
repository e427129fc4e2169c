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
/// byte-swapped views (-B, -S), and the explanation lines -e prints under an error frame. -t z
/// prints the time since the first frame and -t d the time since the previous one: a line alone
/// cannot say which, so a reader classifies the first stamps of a recording
/// (ClassifyCandumpStamps) and turns -t d's into times (CandumpTimeline).
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

/// What a recording's stamps count.
enum class CandumpTimeBase {
  kAbsolute,       ///< Unix time (-l, -L, -t a, asc2log with the ASC's date)
  kSinceFirst,     ///< seconds since the first frame (-t z; asc2log of an ASC without a date)
  kSincePrevious,  ///< seconds since the previous frame (-t d)
};

/// "Unix time", "time since the first frame (candump -t z)", ...
const char* CandumpTimeBaseName(CandumpTimeBase base) noexcept;

/// Stamps a reader looks at before it classifies a recording's time base.
inline constexpr std::size_t kCandumpStampsToClassify = 64;

/// Classifies a recording from its first stamps (in order, microseconds as parsed). Stamps from
/// 2001-09-09 (1e9 s) on are Unix time. Smaller ones count from the recording's start: -t z's
/// never go back, while -t d's go up and down with the gaps between frames (or stay equal, for
/// evenly spaced frames), so stamps that go back more than a tenth as often as they go forward,
/// or never move after the second, are -t d's. Fewer than three stamps: since the first (the
/// first two stamps read the same either way); none: Unix time (nothing to convert).
CandumpTimeBase ClassifyCandumpStamps(const std::int64_t* stamps_us, std::size_t count) noexcept;

/// Turns the stamps of a recording into times (microseconds): as they are, or, for -t d's, each
/// stamp added to the time of the frame before.
class CandumpTimeline {
 public:
  explicit CandumpTimeline(CandumpTimeBase base) : base_(base) {}
  std::int64_t TimeUs(std::int64_t stamp_us) noexcept {
    if (base_ != CandumpTimeBase::kSincePrevious) return stamp_us;
    sum_us_ += stamp_us;
    return sum_us_;
  }
  CandumpTimeBase base() const noexcept { return base_; }

 private:
  CandumpTimeBase base_;
  std::int64_t sum_us_ = 0;
};

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
