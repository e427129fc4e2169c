// pumpthermd: the pump thermal gateway daemon. See `pumpthermd --help`.
#include <fmt/core.h>

#include <CLI/CLI.hpp>
#include <cerrno>
#include <cstring>
#include <fstream>
#include <iostream>
#include <system_error>

#include "daemon/commission.hpp"
#include "daemon/config.hpp"
#include "daemon/gateway.hpp"
#include "daemon/live_loop.hpp"
#include "daemon/log.hpp"
#include "daemon/mqtt_sink.hpp"
#include "daemon/offline.hpp"

namespace {

constexpr int kExitRunFailed = 1;
constexpr int kExitBadInput = 2;
/// A configuration the service refuses (EX_CONFIG of sysexits.h; systemd shows it as
/// "status=78/CONFIG"): the unit's RestartPreventExitStatus= stops restarting, since a restart
/// reads the same file.
constexpr int kExitConfigRefused = 78;

using pumptherm::daemon::ConfigError;
using pumptherm::daemon::DaemonConfig;

/// What a configuration needs to run as the service, beyond loading: an interface to listen on
/// (else the service refuses to start) and a pump (else it would estimate nothing).
void RequireServiceConfig(const DaemonConfig& c) {
  if (c.interfaces.empty())
    throw ConfigError(c.source +
                      ": no [[can]] interface: the service would not start (add [[can]] with "
                      "interface = \"can0\"; pumpthermd -r LOG runs a recording without one)");
  if (c.pumps.empty())
    throw ConfigError(c.source +
                      ": no [[pump]]: the gateway would estimate nothing, only count frames and "
                      "send its heartbeat (add [[pump]] with name and node_id)");
}

/// --check-config FILE [--against LOG]: exit 0 valid (and, against a recording, nothing to
/// change), 2 refused or something to change, 1 the recording cannot be read.
int CheckConfig(const std::string& path, const std::string& against, bool lag_fit) {
  using namespace pumptherm::daemon;
  try {
    const DaemonConfig c = LoadConfig(path);
    if (const std::string w = ConfigPermissionWarning(path); !w.empty())
      Log(LogLevel::kWarning, "{}", w);
    Gateway g(c);  // also checks the DBC, mapping, motors and models it names
    g.LoadClearKeys(CredentialsDirectory());  // and the key files' permissions
    CheckMqttFiles(c);                        // the broker's CA, the client's key, the password
    RequireServiceConfig(c);
    if (!against.empty()) {
      CommissionOptions options;
      if (!lag_fit) options.lag_grid_s.clear();
      const CommissionResult r = CommissionAgainst(c, against, options);
      fmt::print("{}", r.report);
      return r.changes.empty() ? 0 : kExitBadInput;
    }
    fmt::print("{}: OK ({} interface{}, {} pump{})\n", path, c.interfaces.size(),
               c.interfaces.size() == 1 ? "" : "s", c.pumps.size(), c.pumps.size() == 1 ? "" : "s");
    return 0;
  } catch (const ConfigError& e) {
    Log(LogLevel::kError, "{}", e.what());
    return kExitBadInput;
  } catch (const std::exception& e) {
    Log(LogLevel::kError, "{}", e.what());
    return kExitRunFailed;
  }
}

}  // namespace

int main(int argc, char** argv) {
  using namespace pumptherm::daemon;
  CLI::App app{
      "pumpthermd: pump thermal gateway (SocketCAN telemetry in; temperatures and alarms "
      "out on CAN and LCM)"};
  std::string config_path;
  std::string log_path;
  std::string check_path;
  OfflineOptions offline;
  app.add_option("-c,--config", config_path, "configuration file (TOML)");
  app.add_option("-r,--read", log_path,
                 "process a candump log (FILE, or - for stdin) instead of live interfaces, as fast "
                 "as possible, with the log's timestamps as the clock");
  app.add_option("--check-config", check_path,
                 "validate a configuration file (and the files it names) and exit");
  std::string against_path;
  app.add_option("--against", against_path,
                 "with --check-config: commission the configuration against a candump recording "
                 "of its bus (node IDs, rates, plausible values, clocks, the sensor's lag) and "
                 "report what to change");
  bool no_lag_fit = false;
  app.add_flag("--no-lag-fit", no_lag_fit,
               "with --against: skip the frame sensor's lag fit (it runs the pipeline once per "
               "candidate lag, about 15 times the cost of one run)");
  app.add_option("--output-log", offline.output_log,
                 "with -r: write the frames the gateway sends as a candump log");
  app.add_option("--lcm-log", offline.lcm_log,
                 "with -r: write the LCM messages as an LCM log file (lcm-logplayer plays it)");
  app.add_option("--csv-dir", offline.csv_dir,
                 "with -r: write <pump>.csv per pump, a row per thermal step");
  app.add_option("--csv-time-origin", offline.csv_time_origin_s,
                 "with --csv-dir: Unix time (s) that becomes time_s = 0 in the CSV files "
                 "(default: the recording's first whole second; 0: Unix time)");
  app.add_flag("--table", offline.table,
               "print a table of the pumps on stderr while running (live or with -r)");
  auto* table_period =
      app.add_option("--table-period", offline.table_period_s,
                     "with --table: seconds between tables (of log time with -r, wall-clock live; "
                     "default 60 with -r, 5 live)")
          ->check(CLI::PositiveNumber);
  app.add_option("--pace", offline.pace,
                 "with -r: log seconds per wall-clock second (0 = as fast as possible)")
      ->check(CLI::NonNegativeNumber);
  app.set_version_flag("--version", "pumpthermd " PUMPTHERM_VERSION);
  app.footer(
      "Examples:\n"
      "  pumpthermd --config /etc/pumptherm/pumpthermd.toml     live, as the service runs it\n"
      "  pumpthermd --config c.toml -r rec.log --csv-dir out    offline, estimates per pump\n"
      "  pumpthermd -r recording.log                            offline, per-ID frame counts\n"
      "  candump -L vcan0 | pumpthermd -r -                     offline from a pipe\n"
      "  pumpthermd --check-config pumpthermd.toml              validate and exit\n"
      "  pumpthermd --check-config c.toml --against bus.log     commission against a recording\n"
      "Exit codes: 0 success, 1 the run failed (resource, I/O), 2 bad configuration or usage\n"
      "(or, --against, something to change), 78 a configuration the service refuses.");
  try {
    app.parse(argc, argv);
  } catch (const CLI::ParseError& e) {
    const int code = app.exit(e);
    return code == 0 ? 0 : kExitBadInput;
  }

  if (!against_path.empty() && check_path.empty()) {
    Log(LogLevel::kError, "--against LOG goes with --check-config FILE");
    return kExitBadInput;
  }
  if (!check_path.empty()) return CheckConfig(check_path, against_path, !no_lag_fit);

  DaemonConfig config;
  try {
    if (!config_path.empty()) {
      config = LoadConfig(config_path);
      if (const std::string w = ConfigPermissionWarning(config_path); !w.empty())
        Log(LogLevel::kWarning, "{}", w);
    }
  } catch (const ConfigError& e) {
    Log(LogLevel::kError, "{}", e.what());
    return log_path.empty() ? kExitConfigRefused : kExitBadInput;
  }

  if (!log_path.empty()) {
    // Lines carry the recording's time from its first frame on (RunOffline), none before it.
    SetLogTime(kNoLogTime);
    std::unique_ptr<Gateway> gateway;
    try {
      gateway = std::make_unique<Gateway>(config);
    } catch (const ConfigError& e) {
      Log(LogLevel::kError, "{}", e.what());
      return kExitBadInput;
    }
    std::ifstream file;
    std::istream* in = &std::cin;
    const std::string source = log_path == "-" ? "<stdin>" : log_path;
    if (log_path != "-") {
      try {
        file = OpenLog(log_path);
      } catch (const std::exception& e) {
        Log(LogLevel::kError, "{}", e.what());
        return kExitRunFailed;
      }
      in = &file;
    }
    // Offline runs publish LCM only to the log file: say so, a configured lcm.url stays silent.
    if (!gateway->pumps().empty())
      Log(LogLevel::kNotice,
          "offline: LCM is written only to --lcm-log ({}), not to lcm.url ({}); "
          "replay it with lcm-logplayer --lcm-url=URL FILE",
          offline.lcm_log.empty() ? "none given" : offline.lcm_log,
          config.lcm.url.empty() ? "unset" : config.lcm.url);
    // The MQTT sink, when configured, then NDEATH. As fast as possible every step is sent (Offer
    // waits for room: such a run has no timing to keep); paced, a full queue drops the oldest
    // step, as live.
    std::unique_ptr<MqttSink> mqtt;
    OfflineResult r;
    try {
      if (config.mqtt.enabled) {
        CheckMqttFiles(config);
        mqtt = std::make_unique<MqttSink>(config.mqtt, config.gateway.name, *gateway,
                                          offline.pace == 0.0);
        // The health messages carry the counts as of the step before (live, the loop hands them
        // in before each Advance).
        offline.after_advance = [&](const Gateway& g, std::int64_t) {
          mqtt->Offer(g);
          gateway->SetMqttHealth(mqtt->Health());
        };
      }
      r = RunOffline(*in, source, *gateway, offline);
      if (mqtt) {
        mqtt->Stop(30.0);
        fmt::print("{}\n", mqtt->StatusText());
      }
    } catch (const std::exception& e) {
      Log(LogLevel::kError, "{}", e.what());
      return kExitRunFailed;
    }
    if (in->bad()) {
      Log(LogLevel::kError, "{}: read error: {}", source, std::strerror(errno));
      return kExitRunFailed;
    }
    try {
      RequireFrames(r, source);
    } catch (const std::exception& e) {
      Log(LogLevel::kError, "{}", e.what());
      return kExitRunFailed;
    }
    fmt::print("{}: {} frames, {} CAN IDs, {} malformed lines skipped\n", source, r.frames,
               gateway->counter().counts().size(), r.bad_lines);
    if (r.untimed_lines > 0)
      fmt::print("{}: {} lines without a timestamp skipped (warned above)\n", source,
                 r.untimed_lines);
    if (r.time_steps_back > 0)
      fmt::print("{}: time went back {} times (warned above)\n", source, r.time_steps_back);
    fmt::print("{}", gateway->counter().CountTable());
    if (!gateway->pumps().empty()) {
      fmt::print("sent {} frames and {} LCM messages; {} unknown-ID and {} short frames ignored\n",
                 r.frames_out, r.lcm_out, gateway->counters().rx_unknown_id,
                 gateway->counters().rx_bad_length);
      fmt::print("{}", gateway->PumpTable());
      // What each pump's pipeline did: the soak checks thermal_steps against elapsed / period.
      fmt::print("{:<12} {:>12} {:>12} {:>12} {:>9} {:>9} {:>9} {:>13} {:>7}\n", "pump",
                 "fast_frames", "status", "samples", "unpaired", "lost", "rejected",
                 "thermal_steps", "resets");
      for (const auto& p : gateway->pumps()) {
        const PumpCounters& c = p->counters();
        fmt::print("{:<12} {:>12} {:>12} {:>12} {:>9} {:>9} {:>9} {:>13} {:>7}\n", p->config().name,
                   c.fast_frames, c.status_frames, c.samples, c.unpaired, c.lost_frames,
                   c.rejected_values, c.thermal_steps, c.filter_resets);
      }
      // A configured pump that no frame reached: a wrong node_id or interface, or the wrong log.
      for (const auto& p : gateway->pumps()) {
        if (p->counters().fast_frames + p->counters().status_frames > 0) continue;
        Log(LogLevel::kWarning,
            "{}: pump {} (node {} on {}) heard no frame in the recording: no estimate "
            "(pumpthermd --check-config CONFIG --against LOG names the nodes heard)",
            source, p->config().name, p->config().node_id, p->config().interface);
      }
    }
    return 0;
  }

  if (config_path.empty()) {
    Log(LogLevel::kError,
        "nothing to do: give --config FILE for live interfaces or -r LOG for a log");
    return kExitBadInput;
  }
  if (config.pumps.empty() && !config.interfaces.empty())
    Log(LogLevel::kWarning, "{}: no [[pump]]: only counting frames and sending the heartbeat",
        config.source);
  try {
    LiveOptions live;
    live.table = offline.table;
    if (table_period->count() > 0) live.table_period_s = offline.table_period_s;
    LiveLoop loop(config, config_path, live);
    const int code = loop.Run();
    fmt::print("{}", loop.Summary());
    std::fflush(stdout);
    return code;
  } catch (const ConfigError& e) {
    Log(LogLevel::kError, "{}", e.what());
    return kExitConfigRefused;
  } catch (const std::exception& e) {
    Log(LogLevel::kError, "{}", e.what());
    return kExitRunFailed;
  }
}
