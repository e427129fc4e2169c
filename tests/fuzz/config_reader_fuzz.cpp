// libFuzzer target: the daemon's configuration reader (daemon/config.hpp) on arbitrary text.
// A ConfigError is the expected answer to bad input, and its message must name the file
// ("fuzz.toml:"). Any other exception, a crash or a sanitizer report is a finding, and so is an
// accepted configuration that breaks the documented ranges (a pump without a name, a
// non-positive period, a receive buffer outside 0 or 4096..256 MiB).
#include <cmath>
#include <cstdint>
#include <cstdlib>
#include <string>

#include "daemon/config.hpp"

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  using namespace pumptherm::daemon;
  const std::string text(reinterpret_cast<const char*>(data), size);
  DaemonConfig config;
  try {
    config = ParseConfig(text, "/etc/pumptherm/fuzz.toml");
  } catch (const ConfigError& e) {
    if (std::string(e.what()).rfind("/etc/pumptherm/fuzz.toml", 0) != 0) std::abort();
    return 0;
  }
  if (!(config.gateway.thermal_period_s > 0.0) || !std::isfinite(config.gateway.thermal_period_s))
    std::abort();
  if (!(config.lcm.period_s > 0.0) || !(config.lcm.health_period_s > 0.0)) std::abort();
  for (const auto& i : config.interfaces) {
    if (i.rx_buffer_bytes != 0 &&
        (i.rx_buffer_bytes < kMinRxBufferBytes || i.rx_buffer_bytes > kMaxRxBufferBytes))
      std::abort();
  }
  for (const auto& p : config.pumps) {
    if (p.name.empty()) std::abort();
    if (!std::isfinite(p.winding_sd_K) || !(p.winding_sd_K > 0.0)) std::abort();
    if (p.name.find_first_of(" \t/") != std::string::npos) std::abort();
    if (!(p.alarms.monitor.sensor_min_degC < p.alarms.monitor.sensor_max_degC)) std::abort();
    for (const auto& [node, levels] : p.alarms.levels) {
      if (!(levels.limits.warning_degC <= levels.limits.trip_degC)) std::abort();
    }
  }
  return 0;
}
