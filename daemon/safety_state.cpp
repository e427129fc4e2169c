#include "daemon/safety_state.hpp"

#include <fmt/format.h>
#include <sodium.h>
#include <toml++/toml.h>

#include <array>
#include <cmath>
#include <sstream>

namespace pumptherm::daemon {
namespace {

constexpr std::string_view kChecksumLine = "# blake2b-256 ";
constexpr std::int64_t kVersion = 1;

std::string Checksum(std::string_view body) {
  static const int init = sodium_init();
  (void)init;  // crypto_generichash needs no initialised state; kept for libsodium's rule
  std::array<unsigned char, 32> h{};
  crypto_generichash(h.data(), h.size(), reinterpret_cast<const unsigned char*>(body.data()),
                     body.size(), nullptr, 0);
  std::string out;
  for (unsigned char b : h) out += fmt::format("{:02x}", b);
  return out;
}

/// One pump's latches from its table; false for a damaged pair of arrays.
bool ReadLatches(const toml::table& t, std::vector<SafetyState::Latch>& out) {
  const toml::array* nodes = t["latched_trip_nodes"].as_array();
  const toml::array* values = t["latched_trip_values_degC"].as_array();
  if (!nodes || !values || nodes->size() != values->size()) return false;
  for (std::size_t k = 0; k < nodes->size(); ++k) {
    const auto node = (*nodes)[k].value<std::string>();
    const auto value = (*values)[k].value<double>();
    if (!node || node->empty() || !value || !std::isfinite(*value)) return false;
    out.push_back({*node, *value});
  }
  return true;
}

}  // namespace

std::string FormatSafetyState(const SafetyState& s) {
  toml::table root;
  root.insert("version", kVersion);
  root.insert("refused_up_to_us", s.refused_up_to_us);
  toml::table pumps;
  for (const auto& [pump, latches] : s.latched) {
    // Two parallel arrays, as in state.toml (toml++ 3.3 misprints arrays of nested tables).
    toml::array nodes, values;
    for (const auto& l : latches) {
      nodes.push_back(l.node);
      values.push_back(l.value_degC);
    }
    pumps.insert(pump, toml::table{{"latched_trip_nodes", std::move(nodes)},
                                   {"latched_trip_values_degC", std::move(values)}});
  }
  root.insert("pump", std::move(pumps));
  toml::table counters;
  for (const auto& [pump, keys] : s.counters) {
    toml::table t;
    for (const auto& [key, counter] : keys) t.insert(key, counter);
    counters.insert(pump, std::move(t));
  }
  root.insert("clear_counters", std::move(counters));
  std::ostringstream ss;
  ss << "# pumpthermd safety state: latched trips and clear counters (docs/daemon.md).\n"
     << "# Written before a clear acts; do not edit (the checksum below guards it).\n"
     << root << "\n";
  const std::string body = ss.str();
  return body + std::string(kChecksumLine) + Checksum(body) + "\n";
}

std::optional<SafetyState> ParseSafetyState(std::string_view text, std::string* problem) {
  const std::size_t at = text.rfind(kChecksumLine);
  if (at == std::string_view::npos || (at > 0 && text[at - 1] != '\n')) {
    *problem = "no checksum line (cut short or not written by pumpthermd)";
    return std::nullopt;
  }
  std::string_view sum = text.substr(at + kChecksumLine.size());
  while (!sum.empty() && (sum.back() == '\n' || sum.back() == '\r')) sum.remove_suffix(1);
  const std::string_view body = text.substr(0, at);
  if (sum != Checksum(body)) {
    *problem = "the checksum does not match its contents (damaged)";
    return std::nullopt;
  }
  toml::table root;
  try {
    root = toml::parse(body, std::string_view("safety state"));
  } catch (const toml::parse_error& e) {
    *problem = fmt::format("does not parse (line {}): {}", e.source().begin.line, e.description());
    return std::nullopt;
  }
  if (root["version"].value_or<std::int64_t>(0) != kVersion) {
    *problem = "unknown version";
    return std::nullopt;
  }
  SafetyState s;
  const auto floor = root["refused_up_to_us"].value<std::int64_t>();
  const toml::table* pumps = root["pump"].as_table();
  const toml::table* counters = root["clear_counters"].as_table();
  if (!floor || !pumps || !counters) {
    *problem = "refused_up_to_us, [pump] or [clear_counters] is missing";
    return std::nullopt;
  }
  s.refused_up_to_us = *floor;
  for (const auto& [pump, node] : *pumps) {
    const toml::table* t = node.as_table();
    std::vector<SafetyState::Latch>& latches = s.latched[std::string(pump.str())];
    if (!t || !ReadLatches(*t, latches)) {
      *problem = fmt::format("the latched trips of pump '{}' are damaged", pump.str());
      return std::nullopt;
    }
  }
  for (const auto& [pump, node] : *counters) {
    const toml::table* t = node.as_table();
    if (!t) {
      *problem = fmt::format("the clear counters of pump '{}' are damaged", pump.str());
      return std::nullopt;
    }
    for (const auto& [key, value] : *t) {
      const auto v = value.value<std::int64_t>();
      if (!v) {
        *problem =
            fmt::format("clear counter {} of pump '{}' is not an integer", key.str(), pump.str());
        return std::nullopt;
      }
      s.counters[std::string(pump.str())][std::string(key.str())] = *v;
    }
  }
  return s;
}

bool WrittenBeforeSafetyFile(std::string_view state_toml) {
  try {
    const toml::table root = toml::parse(state_toml, std::string_view("saved state"));
    return root["clear_auth"].as_table() != nullptr;
  } catch (const toml::parse_error&) {
    return false;
  }
}

}  // namespace pumptherm::daemon
