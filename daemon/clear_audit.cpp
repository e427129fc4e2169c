#include "daemon/clear_audit.hpp"

#include <fmt/format.h>

namespace pumptherm::daemon {
namespace {

constexpr std::string_view kOtherSources = "(other sources)";

}  // namespace

ClearAudit::ClearAudit(int burst, double window_s)
    : limiter_(burst, window_s), burst_(burst), window_s_(window_s) {}

bool ClearAudit::Refused(std::int64_t now_us, std::string_view source, std::string_view reason,
                         std::vector<Summary>* before) {
  std::uint64_t held_back = 0;
  if (limiter_.Allow(now_us, &held_back)) {
    if (held_back > 0) *before = Summaries();
    return true;
  }
  std::string key(source);
  if (held_.count(key) == 0 && held_.size() >= kMaxSources) key = kOtherSources;
  Held& h = held_[key];
  ++h.count;
  ++h.reasons[std::string(reason)];
  return false;
}

std::vector<ClearAudit::Summary> ClearAudit::TakeSummaries(std::int64_t now_us, bool stop) {
  if (held_.empty()) return {};
  // The limiter reports its held-back lines once their window is over; at stop, now.
  if (limiter_.TakeHeldBack(now_us) == 0 && !stop) return {};
  return Summaries();
}

std::vector<ClearAudit::Summary> ClearAudit::Summaries() {
  std::vector<Summary> out;
  for (const auto& [source, h] : held_) {
    Summary s;
    s.source = source;
    s.count = h.count;
    for (const auto& [reason, n] : h.reasons)
      s.reasons += fmt::format("{}{} {}", s.reasons.empty() ? "" : ", ", reason, n);
    s.text = fmt::format(
        "{} refused alarm clear(s) from {} not logged (at most {} lines per {:.0f} s; all "
        "counted in clears_refused): {}",
        s.count, source, burst_, window_s_, s.reasons);
    out.push_back(std::move(s));
  }
  held_.clear();
  return out;
}

}  // namespace pumptherm::daemon
