// Clearing latched trips (docs/threat-model.md): the authenticated LCM clear
// (Gateway::ClearFromLcm, Gateway::LoadClearKey), the CAN clear and its rate limit, and the refused
// clears' journal lines.
#include <algorithm>

#include "daemon/gateway.hpp"
#include "daemon/log.hpp"
#include "protocol/lcm/channels.hpp"

namespace pumptherm::daemon {

void Gateway::LoadClearKey(const std::string& credentials_dir) {
  if (const auto key = LoadConfiguredClearKey(config_, credentials_dir)) {
    clear_auth_.SetKey(*key);
    return;
  }
  // Not an error: a configuration from before the key keeps its gateway running (a gateway
  // that does not start raises no alarm at all); its LCM clears are refused and counted.
  if (!config_.alarms.clear_lcm_sources.empty()) {
    Log(LogLevel::kWarning,
        "{}: alarms.clear_lcm_sources is set but alarms.clear_key_file is not: every LCM "
        "clear will be refused (docs/threat-model.md)",
        config_.source);
  }
}

bool Gateway::ClearFromLcm(const pumptherm::alarm_clear_t* m, std::int64_t now_us,
                           OutputSink& sink) {
  using R = pumptherm::alarm_clear_reply_t;
  if (!m) {
    ++counters_.clears_refused;
    ++counters_.clears_unauthenticated;
    if (std::string note; AllowRefusedClearLog(&note)) {
      Log(LogLevel::kWarning,
          "alarm clear refused: the message does not decode as alarm_clear_t (an old sender?){}",
          note);
    }
    return false;
  }
  const auto pump = std::find_if(pumps_.begin(), pumps_.end(),
                                 [&](const auto& p) { return p->config().name == m->pump; });
  if (pump == pumps_.end()) {
    ++counters_.clears_refused;
    if (std::string note; AllowRefusedClearLog(&note)) {
      Log(LogLevel::kWarning, "alarm clear for unknown pump '{}' from '{}' ignored{}", m->pump,
          m->source, note);
    }
    return false;
  }
  const auto& sources = (*pump)->config().alarms.clear_lcm_sources;
  const bool source_allowed = std::find(sources.begin(), sources.end(), m->source) != sources.end();
  std::string reason;
  const std::int8_t result = clear_auth_.Check(*m, source_allowed, now_us, &reason);
  const std::string comment = m->comment.empty() ? "" : ": " + m->comment;
  if (result == R::RESULT_ACCEPTED) {
    ++counters_.clears_accepted;
    MarkAllDue();
    reason = (*pump)->ClearTrips() ? "latched trip cleared" : "nothing was latched";
    Log(LogLevel::kNotice, "pump {}: alarm clear from '{}' (counter {}) accepted ({}){}", m->pump,
        m->source, m->counter, reason, comment);
  } else {
    ++counters_.clears_refused;
    if (result == R::RESULT_BAD_MAC || result == R::RESULT_NO_KEY)
      ++counters_.clears_unauthenticated;
    if (std::string note; AllowRefusedClearLog(&note)) {
      Log(LogLevel::kWarning, "pump {}: alarm clear from '{}' (counter {}) refused: {}{}{}",
          m->pump, m->source, m->counter, reason, comment, note);
    }
  }
  // The snapshot lags a clear until the next thermal step; the saved latch does not.
  const bool latched = !(*pump)->Save().latched_trips.empty();
  PublishClearReply(clear_auth_.Reply(*m, result, reason, latched, now_us), now_us, sink);
  return result == R::RESULT_ACCEPTED;
}

void Gateway::PublishClearReply(const pumptherm::alarm_clear_reply_t& reply, std::int64_t now_us,
                                OutputSink& sink) {
  std::vector<std::uint8_t> bytes(static_cast<std::size_t>(reply.getEncodedSize()));
  reply.encode(bytes.data(), 0, static_cast<int>(bytes.size()));
  const std::string channel = lcm_channels::PumpChannelName(
      config_.lcm.channel_prefix, reply.pump, lcm_channels::PumpChannel::kAlarmClearReply);
  if (sink.PublishLcm(channel, now_us, bytes)) {
    ++counters_.lcm_published;
  } else {
    ++counters_.lcm_failed;
  }
}

void Gateway::RateLimitedClear(PumpIo& io, const std::string& pump, const std::string& iface) {
  ++counters_.clears_rate_limited;
  if (io.clear_repeat_logged) return;  // a held button: one line per burst, every repeat counted
  io.clear_repeat_logged = true;
  Log(LogLevel::kNotice,
      "pump {}: PUMP_CLEAR from can:{} within 2 s of the last one ignored (rate limit; further "
      "repeats are counted, not logged)",
      pump, iface);
}

bool Gateway::Clear(const std::string& pump_name, const std::string& source,
                    const std::string& comment) {
  for (auto& pump : pumps_) {
    if (pump->config().name != pump_name) continue;
    const auto& a = pump->config().alarms;
    bool allowed = false;
    if (source.rfind("can:", 0) == 0) {
      const std::string iface = source.substr(4);
      allowed = std::find(a.clear_can_interfaces.begin(), a.clear_can_interfaces.end(), iface) !=
                a.clear_can_interfaces.end();
    } else {
      // A source name alone proves nothing: LCM clears go through ClearFromLcm.
      ++counters_.clears_refused;
      ++counters_.clears_unauthenticated;
      if (std::string note; AllowRefusedClearLog(&note)) {
        Log(LogLevel::kWarning,
            "pump {}: alarm clear from '{}' refused (no authentication code){}{}", pump_name,
            source, comment.empty() ? "" : ": " + comment, note);
      }
      return false;
    }
    if (!allowed) {
      ++counters_.clears_refused;
      if (std::string note; AllowRefusedClearLog(&note)) {
        Log(LogLevel::kWarning,
            "pump {}: alarm clear from '{}' refused (not a configured source){}{}", pump_name,
            source, comment.empty() ? "" : ": " + comment, note);
      }
      return false;
    }
    ++counters_.clears_accepted;
    MarkAllDue();
    const bool was = pump->ClearTrips();
    Log(LogLevel::kNotice, "pump {}: alarm clear from '{}' accepted ({}){}", pump_name, source,
        was ? "latched trip cleared" : "nothing was latched",
        comment.empty() ? "" : ": " + comment);
    return true;
  }
  ++counters_.clears_refused;
  if (std::string note; AllowRefusedClearLog(&note)) {
    Log(LogLevel::kWarning, "alarm clear for unknown pump '{}' from '{}' ignored{}", pump_name,
        source, note);
  }
  return false;
}

bool Gateway::AllowRefusedClearLog(std::string* note) {
  // On the pipeline's clock (the last Advance): monotonic live, the log's time offline.
  std::uint64_t held_back = 0;
  if (!refused_clear_log_.Allow(last_now_us_, &held_back)) return false;
  if (held_back > 0) {
    *note =
        fmt::format(" ({} refused clear(s) before this one not logged: at most {} lines per {} s)",
                    held_back, kRefusedClearLogBurst, kRefusedClearLogWindow_s);
  }
  return true;
}

void Gateway::ReportRefusedClearsHeldBack(std::int64_t now_us) {
  if (const std::uint64_t n = refused_clear_log_.TakeHeldBack(now_us); n > 0) {
    Log(LogLevel::kWarning,
        "{} refused alarm clear(s) not logged (at most {} lines per {} s; all counted in "
        "clears_refused)",
        n, kRefusedClearLogBurst, kRefusedClearLogWindow_s);
  }
}

}  // namespace pumptherm::daemon
