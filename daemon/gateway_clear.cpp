// Clearing latched trips (docs/threat-model.md): the signed LCM clear (Gateway::ClearFromLcm,
// Gateway::LoadClearKeys), the CAN clear and its rate limit, the audit trail of refusals, and
// the durability of a clear: its counter and the latches left are committed before it acts.
#include <algorithm>

#include "daemon/gateway.hpp"
#include "daemon/log.hpp"
#include "protocol/lcm/channels.hpp"

namespace pumptherm::daemon {
namespace {

/// A short label per check, for the journal's REASON= field and the audit's summaries.
const char* CheckLabel(ClearCheck c) {
  switch (c) {
    case ClearCheck::kNoGatewayKey:
      return "no gateway key";
    case ClearCheck::kOtherGateway:
      return "other gateway";
    case ClearCheck::kUnknownKey:
      return "unknown key";
    case ClearCheck::kRevokedKey:
      return "revoked key";
    case ClearCheck::kBadTag:
      return "bad tag";
    case ClearCheck::kReplayed:
      return "replayed";
    case ClearCheck::kBadSignature:
      return "bad signature";
    case ClearCheck::kOutsideWindow:
      return "outside window";
    case ClearCheck::kPassed:
      return "passed";
  }
  return "unknown";
}

std::string CommentText(const std::string& comment) {
  return comment.empty() ? "" : ": " + comment;
}

/// One journal line per source of refusals held back, with its fields.
void LogSummaries(const std::vector<ClearAudit::Summary>& summaries) {
  for (const auto& s : summaries) {
    LogFields(LogLevel::kWarning,
              {{"SOURCE", s.source},
               {"RESULT", "refused"},
               {"REASON", s.reasons},
               {"COUNT", std::to_string(s.count)}},
              "{}", s.text);
  }
}

}  // namespace

void Gateway::LoadClearKeys(const std::string& credentials_dir) {
  const ClearAuthConfig& c = config_.clear_auth;
  if (const auto key = LoadConfiguredGatewayKey(config_, credentials_dir))
    clear_auth_.SetGatewayKey(*key);
  for (const ClearOperatorConfig& op : c.operators) {
    try {
      clear_auth_.AddOperator({op.name, op.public_key, op.revoked});
    } catch (const std::invalid_argument& e) {
      throw ConfigError(fmt::format("{}:{}: key 'alarms.clear_operators': {}", config_.source,
                                    op.line, e.what()));
    }
  }
  if (const auto shared = LoadConfiguredClearKey(config_, credentials_dir))
    clear_auth_.SetSharedKey(*shared, config_.alarms.clear_lcm_sources);
  // Not an error: a configuration from before the keys keeps its gateway running (a gateway
  // that does not start raises no alarm at all); its LCM clears are refused and counted.
  const bool wanted = !c.operators.empty() || !config_.alarms.clear_lcm_sources.empty();
  if (wanted && !clear_auth_.has_gateway_key()) {
    Log(LogLevel::kWarning,
        "{}: operators may clear over LCM but gateway.signing_key_file is not set: every LCM "
        "clear will be refused (pumptherm keygen; docs/threat-model.md)",
        config_.source);
  }
  if (!c.key_file.empty() && !c.allow_shared_key) {
    Log(LogLevel::kWarning,
        "{}: alarms.clear_key_file is the shared key of the earlier scheme, which is off: "
        "operators sign with keys of their own (alarms.clear_operators; "
        "alarms.clear_allow_shared_key = true keeps it for a migration, docs/threat-model.md)",
        config_.source);
  }
}

std::size_t Gateway::PumpIndex(const std::string& name) const {
  for (std::size_t p = 0; p < pumps_.size(); ++p) {
    if (pumps_[p]->config().name == name) return p;
  }
  return pumps_.size();
}

bool Gateway::ClearFromLcm(const pumptherm::alarm_clear_t* m, std::int64_t now_us,
                           OutputSink& sink) {
  if (!m) {
    ++counters_.clears_refused;
    ++counters_.clears_unauthenticated;
    LogRefusedClear("", "(undecodable)", "undecodable",
                    "alarm clear refused: the message does not decode as alarm_clear_t (an "
                    "older sender, or not a clear at all)");
    return false;
  }
  const ClearCheckResult check = clear_auth_.Check(*m, now_us);
  const std::size_t p = PumpIndex(m->pump);
  if (p == pumps_.size()) {
    ++counters_.clears_refused;
    if (check.forged()) ++counters_.clears_unauthenticated;
    LogRefusedClear(
        m->pump, check.source, "unknown pump",
        fmt::format("alarm clear for unknown pump '{}' from {} refused", m->pump, check.source));
    return false;
  }
  if (!check.authenticated()) {
    ++counters_.clears_refused;
    if (check.forged()) ++counters_.clears_unauthenticated;
    LogRefusedClear(m->pump, check.source, CheckLabel(check.check),
                    fmt::format("pump {}: alarm clear from {} (counter {}) refused: {}{}", m->pump,
                                check.source, m->counter, check.reason, CommentText(m->comment)));
    return false;  // no answer: a forged or replayed command gets nothing back
  }
  return ActOnSignedClear(p, *m, check, now_us, sink);
}

bool Gateway::ActOnSignedClear(std::size_t p, const pumptherm::alarm_clear_t& m,
                               const ClearCheckResult& check, std::int64_t now_us,
                               OutputSink& sink) {
  using R = pumptherm::alarm_clear_reply_t;
  Pump& pump = *pumps_[p];
  const std::vector<PumpSavedState::LatchedTrip> before = pump.Save().latched_trips;
  std::int8_t result = R::RESULT_ACCEPTED;
  std::string reason;
  std::string error;
  const bool named = !m.node.empty();
  const bool node_latched =
      std::any_of(before.begin(), before.end(), [&](const auto& t) { return t.node == m.node; });
  if (check.check == ClearCheck::kOutsideWindow) {
    result = R::RESULT_OUTSIDE_WINDOW;
    reason = check.reason;
  } else if (named && !node_latched) {
    result = R::RESULT_NODE_NOT_LATCHED;
    reason = fmt::format("node '{}' has no latched trip", m.node);
  } else if (!CommitClear(p, m.node, &m, &error)) {
    result = R::RESULT_NOT_SAVED;
    reason = "the safety state cannot be written (" + error + "): not cleared";
  }
  if (result == R::RESULT_ACCEPTED) {
    clear_auth_.Take(m);
    const std::optional<int> index = named ? pump.LatchIndex(m.node) : std::nullopt;
    const bool was = named ? (index && pump.ClearTrip(*index)) : pump.ClearTrips();
    reason = !was    ? "nothing was latched"
             : named ? fmt::format("latched trip of {} cleared", m.node)
                     : "latched trip cleared";
    ++counters_.clears_accepted;
    MarkAllDue();
    LogFields(
        LogLevel::kNotice,
        {{"PUMP", m.pump}, {"SOURCE", check.source}, {"RESULT", "accepted"}, {"REASON", reason}},
        "pump {}: alarm clear from {} (counter {}) accepted ({}){}", m.pump, check.source,
        m.counter, reason, CommentText(m.comment));
  } else {
    ++counters_.clears_refused;
    const LogLevel level = result == R::RESULT_NOT_SAVED ? LogLevel::kError : LogLevel::kWarning;
    // A signed command is its signer's: logged in full, never held back.
    LogFields(
        level,
        {{"PUMP", m.pump}, {"SOURCE", check.source}, {"RESULT", "refused"}, {"REASON", reason}},
        "pump {}: alarm clear from {} (counter {}) refused: {}{}", m.pump, check.source, m.counter,
        reason, CommentText(m.comment));
  }
  // The snapshot lags a clear until the next thermal step; the saved latch does not.
  const bool latched = !pump.Save().latched_trips.empty();
  PublishClearReply(clear_auth_.Reply(m, result, reason, latched, now_us), now_us, sink);
  return result == R::RESULT_ACCEPTED;
}

bool Gateway::CommitClear(std::size_t p, const std::string& node, const pumptherm::alarm_clear_t* m,
                          std::string* error) {
  if (!safety_commit_) return true;
  SafetyState next = CollectSafetyState();
  auto& latches = next.latched[pumps_[p]->config().name];
  latches.erase(std::remove_if(latches.begin(), latches.end(),
                               [&](const auto& l) { return node.empty() || l.node == node; }),
                latches.end());
  if (m) {
    std::int64_t& last = next.counters[m->pump][m->key_id];
    last = std::max(last, m->counter);
  }
  return safety_commit_(FormatSafetyState(next), error);
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
  const std::size_t p = PumpIndex(pump_name);
  if (p == pumps_.size()) {
    ++counters_.clears_refused;
    LogRefusedClear(
        pump_name, source, "unknown pump",
        fmt::format("alarm clear for unknown pump '{}' from '{}' ignored", pump_name, source));
    return false;
  }
  Pump& pump = *pumps_[p];
  const auto& a = pump.config().alarms;
  if (source.rfind("can:", 0) != 0) {
    // A source name alone proves nothing: LCM clears go through ClearFromLcm.
    ++counters_.clears_refused;
    ++counters_.clears_unauthenticated;
    LogRefusedClear(pump_name, source, "no signature",
                    fmt::format("pump {}: alarm clear from '{}' refused (not signed){}", pump_name,
                                source, CommentText(comment)));
    return false;
  }
  const std::string iface = source.substr(4);
  if (std::find(a.clear_can_interfaces.begin(), a.clear_can_interfaces.end(), iface) ==
      a.clear_can_interfaces.end()) {
    ++counters_.clears_refused;
    LogRefusedClear(pump_name, source, "not a configured source",
                    fmt::format("pump {}: alarm clear from '{}' refused (not a configured "
                                "source){}",
                                pump_name, source, CommentText(comment)));
    return false;
  }
  std::string error;
  if (!CommitClear(p, "", nullptr, &error)) {
    ++counters_.clears_refused;
    LogFields(
        LogLevel::kError,
        {{"PUMP", pump_name}, {"SOURCE", source}, {"RESULT", "refused"}, {"REASON", "not saved"}},
        "pump {}: alarm clear from '{}' refused: the safety state cannot be written ({}): "
        "not cleared",
        pump_name, source, error);
    return false;
  }
  ++counters_.clears_accepted;
  MarkAllDue();
  const bool was = pump.ClearTrips();
  const std::string reason = was ? "latched trip cleared" : "nothing was latched";
  LogFields(LogLevel::kNotice,
            {{"PUMP", pump_name}, {"SOURCE", source}, {"RESULT", "accepted"}, {"REASON", reason}},
            "pump {}: alarm clear from '{}' accepted ({}){}", pump_name, source, reason,
            CommentText(comment));
  return true;
}

void Gateway::LogRefusedClear(const std::string& pump, const std::string& source,
                              const std::string& reason, const std::string& text) {
  // On the pipeline's clock (the last Advance): monotonic live, the log's time offline.
  std::vector<ClearAudit::Summary> before;
  const bool log = clear_audit_.Refused(last_now_us_, source, reason, &before);
  LogSummaries(before);
  if (!log) return;
  LogFields(LogLevel::kWarning,
            {{"PUMP", pump}, {"SOURCE", source}, {"RESULT", "refused"}, {"REASON", reason}}, "{}",
            text);
}

void Gateway::ReportRefusedClearsHeldBack(std::int64_t now_us) {
  LogSummaries(clear_audit_.TakeSummaries(now_us, false));
}

void Gateway::FlushClearAudit() { LogSummaries(clear_audit_.TakeSummaries(last_now_us_, true)); }

}  // namespace pumptherm::daemon
