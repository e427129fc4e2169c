#include "tools/pumptherm/recording_pump.hpp"

#include <fmt/core.h>

#include <algorithm>
#include <fstream>
#include <iostream>
#include <memory>
#include <sstream>

#include "daemon/gateway.hpp"
#include "daemon/offline.hpp"
#include "protocol/candump_log.hpp"
#include "tools/pumptherm/subcommand.hpp"

namespace pumptherm::tools {
namespace {

/// The first interface named in the candump lines of `in`, or "" (reads only up to it).
std::string FirstInterface(std::istream& in) {
  std::string line;
  while (std::getline(in, line)) {
    const protocol::CandumpParse p = protocol::ParseCandumpLine(line);
    if (p.ok && !p.skip) return std::string(p.record.interface);
  }
  return {};
}

/// The recording as a stream the daemon's offline loop reads block by block, as `pumpthermd -r`
/// does: a file is opened twice (once to find its first interface when none is named), standard
/// input, which cannot be read twice, is held in memory.
struct RecordingStream {
  std::ifstream file;
  std::istringstream held;
  std::istream* in = nullptr;
  std::string first_interface;
};

void OpenRecording(const std::string& path, bool need_interface, RecordingStream& r) {
  try {
    if (path == "-") {
      std::ostringstream ss;
      ss << std::cin.rdbuf();
      r.held.str(ss.str());
      if (need_interface) {
        r.first_interface = FirstInterface(r.held);
        r.held.clear();
        r.held.seekg(0);
      }
      r.in = &r.held;
      return;
    }
    if (need_interface) {
      std::ifstream peek = daemon::OpenLog(path);
      r.first_interface = FirstInterface(peek);
    }
    r.file = daemon::OpenLog(path);
    r.in = &r.file;
  } catch (const std::runtime_error& e) {
    throw InputError(fmt::format("--log {}", e.what()));
  }
}

}  // namespace

daemon::DaemonConfig ConfigWithPump(const std::string& path, const std::string& name) {
  daemon::DaemonConfig c;
  try {
    c = daemon::LoadConfig(path);
  } catch (const daemon::ConfigError& e) {
    throw InputError(e.what());
  }
  auto it = std::find_if(c.pumps.begin(), c.pumps.end(),
                         [&](const daemon::PumpConfig& p) { return p.name == name; });
  if (name.empty() || it == c.pumps.end()) {
    std::string names;
    for (const auto& p : c.pumps) names += (names.empty() ? "" : ", ") + p.name;
    throw InputError(fmt::format("--pump '{}': {} has no such [[pump]] (it has: {})", name, path,
                                 names.empty() ? "none" : names));
  }
  const daemon::PumpConfig pump = *it;
  c.pumps = {pump};
  return c;
}

PumpRecordingResult RunPumpOnRecording(const PumpRecordingRun& run) {
  RecordingStream log;
  OpenRecording(run.recording.log, run.recording.interface.empty(), log);
  daemon::DaemonConfig c;
  if (!run.config.empty()) {
    c = ConfigWithPump(run.config, run.config_pump);
  } else {
    c.source = run.tool;
    c.dbc.file = run.recording.dbc;
    c.dbc.mapping = run.recording.mapping;
    c.gateway.thermal_period_s = run.thermal_period_s;
    c.pumps.push_back(run.pump);
  }
  // The pump listens on the recording's interface unless one is named.
  c.interfaces.clear();
  daemon::PumpConfig& pump = c.pumps.front();
  pump.interface = !run.recording.interface.empty() ? run.recording.interface : log.first_interface;
  if (pump.interface.empty()) {
    throw InputError(fmt::format("--log {}: no CAN frame in it", run.recording.log));
  }
  c.lcm.url.clear();
  c.gateway.state_directory.clear();
  // The other pumps of the recording are left out on purpose: no warning for each.
  c.gateway.warn_unconfigured_nodes = false;
  std::unique_ptr<daemon::Gateway> gateway;
  try {
    gateway = std::make_unique<daemon::Gateway>(c);
  } catch (const std::exception& e) {
    throw InputError(e.what());
  }
  daemon::OfflineOptions offline;
  offline.csv_file = run.csv_file;
  offline.csv_time_origin_s = run.csv_time_origin_s;
  const std::string source = run.recording.log == "-" ? "<stdin>" : run.recording.log;
  daemon::RunOffline(*log.in, source, *gateway, offline);
  if (gateway->pumps().front()->counters().thermal_steps == 0) {
    throw InputError(fmt::format(
        "{}: no thermal step for node ID {} on {} (no frame of this pump, or none paired)", source,
        pump.node_id, pump.interface));
  }
  return {c, gateway->pumps().front()->motor()};
}

}  // namespace pumptherm::tools
