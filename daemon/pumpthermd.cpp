// pumpthermd: the pump thermal gateway daemon. See `pumpthermd --help`.
#include <fmt/core.h>

#include <CLI/CLI.hpp>
#include <cerrno>
#include <cstring>
#include <fstream>
#include <iostream>
#include <system_error>

#include "daemon/config.hpp"
#include "daemon/gateway.hpp"
#include "daemon/live_loop.hpp"
#include "daemon/log.hpp"
#include "daemon/offline.hpp"

namespace {

constexpr int kExitRunFailed = 1;
constexpr int kExitBadInput = 2;

}  // namespace

int main(int argc, char** argv) {
  using namespace pumptherm::daemon;
  CLI::App app{"pumpthermd: pump thermal gateway (SocketCAN in, temperatures and alarms out)"};
  std::string config_path;
  std::string log_path;
  std::string check_path;
  app.add_option("-c,--config", config_path, "configuration file (TOML)");
  app.add_option("-r,--read", log_path,
                 "process a candump log (FILE, or - for stdin) instead of live interfaces, "
                 "as fast as possible, with the log's timestamps as the clock");
  app.add_option("--check-config", check_path, "validate a configuration file and exit");
  app.set_version_flag("--version", "pumpthermd " PUMPTHERM_VERSION);
  app.footer(
      "Examples:\n"
      "  pumpthermd --config /etc/pumptherm/pumpthermd.toml     live, as the service runs it\n"
      "  pumpthermd -r recording.log                            offline, per-ID frame counts\n"
      "  candump -L vcan0 | pumpthermd -r -                     offline from a pipe\n"
      "  pumpthermd --check-config pumpthermd.toml              validate and exit\n"
      "Exit codes: 0 success, 1 the run failed (resource, I/O), 2 bad configuration or usage.");
  try {
    app.parse(argc, argv);
  } catch (const CLI::ParseError& e) {
    const int code = app.exit(e);
    return code == 0 ? 0 : kExitBadInput;
  }

  if (!check_path.empty()) {
    try {
      const DaemonConfig c = LoadConfig(check_path);
      fmt::print("{}: OK ({} interface{})\n", check_path, c.interfaces.size(),
                 c.interfaces.size() == 1 ? "" : "s");
      return 0;
    } catch (const ConfigError& e) {
      Log(LogLevel::kError, "{}", e.what());
      return kExitBadInput;
    }
  }

  DaemonConfig config;
  try {
    if (!config_path.empty()) config = LoadConfig(config_path);
  } catch (const ConfigError& e) {
    Log(LogLevel::kError, "{}", e.what());
    return kExitBadInput;
  }
  Gateway gateway(config.gateway);

  if (!log_path.empty()) {
    std::ifstream file;
    std::istream* in = &std::cin;
    const std::string source = log_path == "-" ? "<stdin>" : log_path;
    if (log_path != "-") {
      file.open(log_path);
      if (!file) {
        Log(LogLevel::kError, "{}: cannot read the log: {}", log_path, std::strerror(errno));
        return kExitRunFailed;
      }
      in = &file;
    }
    const OfflineResult r = RunOffline(*in, source, gateway);
    if (in->bad()) {
      Log(LogLevel::kError, "{}: read error: {}", source, std::strerror(errno));
      return kExitRunFailed;
    }
    fmt::print("{}: {} frames, {} CAN IDs, {} malformed lines skipped\n", source, r.frames,
               gateway.counts().size(), r.bad_lines);
    fmt::print("{}", gateway.CountTable());
    return 0;
  }

  if (config_path.empty()) {
    Log(LogLevel::kError, "nothing to do: give --config FILE for live interfaces or -r LOG for a log");
    return kExitBadInput;
  }
  try {
    LiveLoop loop(config, gateway);
    const int code = loop.Run();
    fmt::print("{}\n{}", gateway.StatusLine(), gateway.CountTable());
    std::fflush(stdout);
    return code;
  } catch (const std::system_error& e) {
    Log(LogLevel::kError, "{}", e.what());
    return kExitRunFailed;
  }
}
