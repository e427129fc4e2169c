#pragma once
/// LCM channel names of pumptherm (docs/lcm.md), so that the daemon, tools and tests build and
/// parse them in one place:
///
///   <prefix>/<pump>/TELEMETRY     pumptherm::telemetry_t
///   <prefix>/<pump>/TEMPS         pumptherm::temperatures_t
///   <prefix>/<pump>/ALARM         pumptherm::alarm_t
///   <prefix>/<pump>/ALARM_CLEAR   pumptherm::alarm_clear_t (command to the gateway)
///   <prefix>/<pump>/ALARM_CLEAR_REPLY   pumptherm::alarm_clear_reply_t (the gateway's answer)
///   <prefix>/GATEWAY/HEALTH       pumptherm::gateway_health_t
///   <prefix>/GATEWAY/DIGEST       pumptherm::gateway_digest_t (signed list of what was published)
///
/// Pure string handling: no I/O. Names are restricted to ASCII letters, digits, '_', '-' and
/// '.', because they are part of channel names and regular expressions, and because LCM 1.3's
/// Java (lcm-spy) reads strings one byte per char (docs/lcm.md, "Known limitation").

#include <optional>
#include <stdexcept>
#include <string>
#include <string_view>

namespace pumptherm::lcm_channels {

/// The default channel prefix.
inline constexpr std::string_view kDefaultPrefix = "PUMPTHERM";

/// The per-pump channels.
enum class PumpChannel { kTelemetry, kTemperatures, kAlarm, kAlarmClear, kAlarmClearReply };

/// Last path element of a per-pump channel: "TELEMETRY", "TEMPS", "ALARM", "ALARM_CLEAR",
/// "ALARM_CLEAR_REPLY".
constexpr std::string_view Suffix(PumpChannel channel) {
  switch (channel) {
    case PumpChannel::kTelemetry:
      return "TELEMETRY";
    case PumpChannel::kTemperatures:
      return "TEMPS";
    case PumpChannel::kAlarm:
      return "ALARM";
    case PumpChannel::kAlarmClear:
      return "ALARM_CLEAR";
    case PumpChannel::kAlarmClearReply:
      return "ALARM_CLEAR_REPLY";
  }
  return "";
}

/// True if `name` may be a pump name: 1 to 64 ASCII letters, digits, '_', '-' or '.', and not
/// "GATEWAY" (the path element of the gateway's own channels).
constexpr bool IsValidPumpName(std::string_view name) {
  if (name.empty() || name.size() > 64 || name == "GATEWAY") {
    return false;
  }
  for (const char c : name) {
    const bool ok = (c >= 'a' && c <= 'z') || (c >= 'A' && c <= 'Z') || (c >= '0' && c <= '9') ||
                    c == '_' || c == '-' || c == '.';
    if (!ok) {
      return false;
    }
  }
  return true;
}

/// True if `prefix` may be a channel prefix: one or more valid names (IsValidPumpName, except
/// that "GATEWAY" is allowed) joined by '/'.
constexpr bool IsValidPrefix(std::string_view prefix) {
  if (prefix.empty()) {
    return false;
  }
  std::size_t start = 0;
  while (true) {
    const std::size_t slash = prefix.find('/', start);
    const std::string_view part =
        prefix.substr(start, slash == std::string_view::npos ? slash : slash - start);
    if (part != "GATEWAY" && !IsValidPumpName(part)) {
      return false;
    }
    if (slash == std::string_view::npos) {
      return true;
    }
    start = slash + 1;
  }
}

/// `<prefix>/<pump>/<suffix>`. Throws std::invalid_argument naming the bad prefix or pump.
inline std::string PumpChannelName(std::string_view prefix, std::string_view pump,
                                   PumpChannel channel) {
  if (!IsValidPrefix(prefix)) {
    throw std::invalid_argument("invalid LCM channel prefix '" + std::string(prefix) +
                                "' (ASCII letters, digits, '_', '-', '.', parts joined by '/')");
  }
  if (!IsValidPumpName(pump)) {
    throw std::invalid_argument(
        "invalid pump name '" + std::string(pump) +
        "' for LCM channels (1-64 ASCII letters, digits, '_', '-', '.'; not GATEWAY)");
  }
  std::string name(prefix);
  name += '/';
  name += pump;
  name += '/';
  name += Suffix(channel);
  return name;
}

/// `<prefix>/GATEWAY/HEALTH`. Throws std::invalid_argument for a bad prefix.
inline std::string GatewayHealthChannelName(std::string_view prefix) {
  if (!IsValidPrefix(prefix)) {
    throw std::invalid_argument("invalid LCM channel prefix '" + std::string(prefix) + "'");
  }
  return std::string(prefix) + "/GATEWAY/HEALTH";
}

/// `<prefix>/GATEWAY/DIGEST`: the gateway's signed digest of what it published. Throws
/// std::invalid_argument for a bad prefix.
inline std::string GatewayDigestChannelName(std::string_view prefix) {
  if (!IsValidPrefix(prefix)) {
    throw std::invalid_argument("invalid LCM channel prefix '" + std::string(prefix) + "'");
  }
  return std::string(prefix) + "/GATEWAY/DIGEST";
}

/// Regular expression (as lcm::LCM::subscribe takes it) for `channel` of every pump under
/// `prefix`, e.g. `PUMPTHERM/[^/]+/ALARM_CLEAR`. Throws std::invalid_argument for a bad prefix.
inline std::string AllPumpsPattern(std::string_view prefix, PumpChannel channel) {
  if (!IsValidPrefix(prefix)) {
    throw std::invalid_argument("invalid LCM channel prefix '" + std::string(prefix) + "'");
  }
  std::string pattern;
  for (const char c : prefix) {
    if (c == '.') {
      pattern += '\\';  // the only regex metacharacter a valid prefix can hold
    }
    pattern += c;
  }
  pattern += "/[^/]+/";
  pattern += Suffix(channel);
  return pattern;
}

/// The pump and kind of a per-pump channel under `prefix`; nullopt for any other channel
/// (another prefix, the gateway's channel, an unknown suffix or an invalid pump name).
struct ParsedChannel {
  std::string pump;
  PumpChannel channel;
};
inline std::optional<ParsedChannel> ParsePumpChannel(std::string_view prefix,
                                                     std::string_view name) {
  if (name.size() <= prefix.size() + 1 || name.substr(0, prefix.size()) != prefix ||
      name[prefix.size()] != '/') {
    return std::nullopt;
  }
  const std::string_view rest = name.substr(prefix.size() + 1);
  const std::size_t slash = rest.find('/');
  if (slash == std::string_view::npos) {
    return std::nullopt;
  }
  const std::string_view pump = rest.substr(0, slash);
  const std::string_view suffix = rest.substr(slash + 1);
  if (!IsValidPumpName(pump)) {
    return std::nullopt;
  }
  for (const PumpChannel c :
       {PumpChannel::kTelemetry, PumpChannel::kTemperatures, PumpChannel::kAlarm,
        PumpChannel::kAlarmClear, PumpChannel::kAlarmClearReply}) {
    if (suffix == Suffix(c)) {
      return ParsedChannel{std::string(pump), c};
    }
  }
  return std::nullopt;
}

}  // namespace pumptherm::lcm_channels
