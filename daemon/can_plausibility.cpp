#include "daemon/can_plausibility.hpp"

#include <algorithm>
#include <cmath>

namespace pumptherm::daemon {
namespace {

constexpr int kCyclesPerWindow = 20;
constexpr std::int64_t kMinWindowUs = 1'000'000;
constexpr std::int64_t kCounterSpanUs = 10'000'000;  // three bad steps within this

}  // namespace

const char* SecondSenderKindName(SecondSenderKind kind) {
  switch (kind) {
    case SecondSenderKind::kOwnId:
      return "own_id";
    case SecondSenderKind::kTooFast:
      return "too_fast";
    case SecondSenderKind::kCounter:
      return "counter";
  }
  return "unknown";
}

RateCheck::RateCheck(double cycle_s) : cycle_s_(cycle_s) {
  if (!(cycle_s > 0.0)) return;
  const double window_s = std::max(kCyclesPerWindow * cycle_s, kMinWindowUs * 1e-6);
  window_us_ = std::llround(window_s * 1e6);
  const double expected = window_s / cycle_s;
  nominal_ = static_cast<std::uint64_t>(std::ceil(expected)) + 2;
  limit_ = static_cast<std::uint64_t>(std::ceil(3.0 * expected)) + 2;
}

bool RateCheck::OnFrame(std::int64_t t_us) {
  if (window_us_ == 0) return false;
  // A clock step back (offline: a new recording) starts a window afresh.
  if (window_start_us_ < 0 || t_us < window_start_us_) {
    window_start_us_ = t_us;
    count_ = 0;
    previous_ = 0;
  }
  bool too_fast = false;
  if (t_us - window_start_us_ >= window_us_) {
    const double span_s = static_cast<double>(t_us - window_start_us_) * 1e-6;
    last_rate_Hz_ = static_cast<double>(count_) / span_s;
    // A window stretched by a silence holds fewer frames per second: it counts as a full one.
    const bool full = t_us - window_start_us_ < 2 * window_us_;
    too_fast = full && count_ > nominal_ && previous_ > nominal_ && count_ + previous_ > limit_;
    previous_ = full ? count_ : 0;
    window_start_us_ = t_us;
    count_ = 0;
  }
  ++count_;
  return too_fast;
}

bool CounterCheck::OnCounter(std::int64_t t_us, double counter) {
  if (std::isnan(counter) || max_gap_us_ == 0) return false;
  const int c = static_cast<int>(std::lround(counter)) % modulus_;
  const bool continues = last_ >= 0 && t_us >= last_us_ && t_us - last_us_ <= max_gap_us_;
  const int step = ((c - last_) % modulus_ + modulus_) % modulus_;
  last_ = c;
  last_us_ = t_us;
  if (!continues) return false;
  // 1 .. half the range forward: the next value, or frames lost. 0: a repeat; beyond: back.
  if (step >= 1 && step <= modulus_ / 2) return false;
  ++bad_steps_;
  bad_us_[0] = bad_us_[1];
  bad_us_[1] = bad_us_[2];
  bad_us_[2] = t_us;
  return bad_us_[0] >= 0 && t_us - bad_us_[0] <= kCounterSpanUs;
}

}  // namespace pumptherm::daemon
