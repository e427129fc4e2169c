#pragma once
/// Evidence of a second sender on a pump's CAN IDs (docs/threat-model.md, "CAN"): CAN has no
/// sender identity, but a forger who adds frames to a bus leaves traces a receiver can see:
/// frames of the gateway's own output IDs (the gateway never receives what it sends itself), a
/// message arriving faster than its cycle allows, a rolling counter that repeats or runs back.
/// Pure bookkeeping: time enters as an argument; no allocation per frame.

#include <cstdint>

namespace pumptherm::daemon {

/// What kind of evidence.
enum class SecondSenderKind : std::uint8_t { kOwnId = 0, kTooFast = 1, kCounter = 2 };
inline constexpr int kSecondSenderKinds = 3;
/// "own_id", "too_fast", "counter" (the journal's KIND= field).
const char* SecondSenderKindName(SecondSenderKind kind);

/// A message faster than its cycle: frames are counted over windows of 20 cycles (at least
/// 1 s, so timer jitter and frames queued in a burst do not matter). Evidence is two windows in
/// a row each above the cycle's count (plus 2) and together above 1.5 times it (plus 2). A
/// drive whose clock runs a few percent fast stays far below that; a forger who adds one frame
/// per real one doubles it. A sender that stalled and caught up (a replay tool on a loaded
/// machine) fills one window with what the one before it lacked, never two.
class RateCheck {
 public:
  /// `cycle_s`: the message's cycle (the DBC's GenMsgCycleTime); 0 or less: not checked.
  explicit RateCheck(double cycle_s = 0.0);
  /// A frame at `t_us`. Returns true when a window just ended making the evidence above.
  bool OnFrame(std::int64_t t_us);
  /// The rate of the last window that ended (Hz; 0 before one did).
  double last_rate_Hz() const { return last_rate_Hz_; }
  double cycle_s() const { return cycle_s_; }

 private:
  double cycle_s_;
  std::int64_t window_us_ = 0;
  std::uint64_t nominal_ = 0;  // frames per window at the cycle, plus 2
  std::uint64_t limit_ = 0;    // frames per two windows at 1.5 times the cycle, plus 2
  std::int64_t window_start_us_ = -1;
  std::uint64_t count_ = 0;
  std::uint64_t previous_ = 0;  // the last full window's count (0: none)
  double last_rate_Hz_ = 0.0;
};

/// A rolling counter that a single sender cannot produce: two frames less than 1.5 cycles apart
/// (so no frame between them was lost) whose counters are the same, or step back (modulo its
/// range, a step of more than half the range forward). Frames further apart are not compared:
/// after lost frames a 4-bit counter at 100 Hz has wrapped within 160 ms. Three such steps
/// within 10 s are evidence (one can be a bus error's double reception).
class CounterCheck {
 public:
  /// `modulus`: how many values the counter takes (16 for 4 bits); `cycle_s`: the message's
  /// cycle (0 or less: not checked).
  explicit CounterCheck(int modulus = 16, double cycle_s = 0.0)
      : modulus_(modulus),
        max_gap_us_(cycle_s > 0.0 ? static_cast<std::int64_t>(1.5e6 * cycle_s) : 0) {}
  /// The counter of a frame at `t_us` (NaN: not available, ignored). Returns true when this
  /// frame makes the third bad step within 10 s.
  bool OnCounter(std::int64_t t_us, double counter);
  /// Bad steps seen so far.
  std::uint64_t bad_steps() const { return bad_steps_; }

 private:
  int modulus_;
  std::int64_t max_gap_us_;  // frames further apart are not compared
  int last_ = -1;
  std::int64_t last_us_ = -1;
  std::int64_t bad_us_[3] = {-1, -1, -1};  // the last three bad steps, oldest first
  std::uint64_t bad_steps_ = 0;
};

}  // namespace pumptherm::daemon
