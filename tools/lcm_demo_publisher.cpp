/// pumptherm-lcm-demo: publishes every pumptherm LCM type with made-up but plausible values, so
/// that pumptherm-spy, lcm-logger and subscribers can be tried without a daemon or a CAN bus.
/// The values come from a toy warm-up curve plus seeded noise; they are not estimates of any
/// motor. Channels are those of docs/lcm.md.

#include <fmt/core.h>

#include <CLI/CLI.hpp>
#include <algorithm>
#include <chrono>
#include <cmath>
#include <csignal>
#include <cstdint>
#include <lcm/lcm-cpp.hpp>
#include <limits>
#include <map>
#include <pumptherm/alarm_clear_t.hpp>
#include <pumptherm/alarm_t.hpp>
#include <pumptherm/gateway_health_t.hpp>
#include <pumptherm/telemetry_t.hpp>
#include <pumptherm/temperatures_t.hpp>
#include <random>
#include <stdexcept>
#include <string>
#include <thread>
#include <vector>

#include "protocol/lcm/channels.hpp"

namespace {

volatile std::sig_atomic_t g_stop = 0;

extern "C" void OnSignal(int /*signal*/) { g_stop = 1; }

constexpr double kNaN = std::numeric_limits<double>::quiet_NaN();
constexpr double kPi = 3.14159265358979323846;

/// Toy motor of the demo: the TMP of Han 2019 Table 1 (1 pole pair, psi_f 0.0182 Wb,
/// Rs 0.28 ohm, Ls 0.24 mH), used only to make the dq voltages consistent with the currents.
struct DemoMotor {
  double rs_ohm = 0.28;
  double ls_H = 0.24e-3;
  double psi_Wb = 0.0182;
  double pole_pairs = 1.0;
  double rated_rpm = 21000.0;
  double ramp_s = 60.0;  ///< shortened from the paper's 8 minutes so the demo shows a ramp
};

struct Options {
  std::string lcm_url;
  std::string prefix = "PUMPTHERM";
  std::vector<std::string> pumps{"tmp1", "tmp2"};
  std::vector<std::string> nodes{"frame",       "yoke",  "teeth", "slot_winding",
                                 "end_winding", "rotor", "shaft"};
  double telemetry_rate_Hz = 10.0;
  double duration_s = 0.0;
  double clear_period_s = 10.0;
  std::uint32_t seed = 1;
};

/// Publishes one message and counts failures (LCM's publish returns non-zero on failure).
template <typename Message>
void Publish(lcm::LCM& lcm, const std::string& channel, const Message& message,
             std::map<std::string, long>& sent, long& failures) {
  if (lcm.publish(channel, &message) == 0) {
    ++sent[channel];
  } else {
    ++failures;
  }
}

int Run(const Options& options) {
  lcm::LCM lcm(options.lcm_url);
  if (!lcm.good()) {
    throw std::runtime_error(fmt::format("cannot open LCM with URL '{}'", options.lcm_url));
  }
  std::signal(SIGINT, OnSignal);
  std::signal(SIGTERM, OnSignal);

  const DemoMotor motor;
  std::mt19937 rng(options.seed);
  std::normal_distribution<double> unit_noise(0.0, 1.0);
  const auto start = std::chrono::steady_clock::now();
  const auto wall_start = std::chrono::system_clock::now();
  const auto period = std::chrono::duration<double>(1.0 / options.telemetry_rate_Hz);
  const long ticks_per_s = std::max(1L, std::lround(options.telemetry_rate_Hz));
  std::map<std::string, long> sent;
  long failures = 0;

  for (long tick = 0; g_stop == 0; ++tick) {
    const double t_s = static_cast<double>(tick) / options.telemetry_rate_Hz;
    if (options.duration_s > 0.0 && t_s > options.duration_s) {
      break;
    }
    std::this_thread::sleep_until(
        start + std::chrono::duration_cast<std::chrono::steady_clock::duration>(period * tick));
    const std::int64_t utime =
        std::chrono::duration_cast<std::chrono::microseconds>(
            (wall_start +
             std::chrono::duration_cast<std::chrono::system_clock::duration>(period * tick))
                .time_since_epoch())
            .count();
    const bool once_per_s = tick % ticks_per_s == 0;

    for (std::size_t p = 0; p < options.pumps.size(); ++p) {
      const std::string& pump = options.pumps[p];
      using pumptherm::lcm_channels::PumpChannel;
      using pumptherm::lcm_channels::PumpChannelName;
      // Speed: linear ramp to rated, then steady; the load current follows a slow gas-load swing.
      const double speed_rpm = motor.rated_rpm * std::min(1.0, t_s / motor.ramp_s);
      const bool ramping = t_s < motor.ramp_s;
      const double iq_A = (ramping ? 4.0 : 1.5 + 0.5 * std::sin(2.0 * kPi * t_s / 120.0)) +
                          0.2 * static_cast<double>(p);
      const double we_rad_per_s = motor.pole_pairs * speed_rpm * 2.0 * kPi / 60.0;
      // Warm-up: winding heats towards 40 K above ambient with a 10-minute time constant.
      const double ambient_degC = 22.0;
      const double rise_K = 40.0 * (1.0 - std::exp(-t_s / 600.0));

      pumptherm::telemetry_t telemetry;
      telemetry.utime = utime;
      telemetry.pump = pump;
      telemetry.node_id = static_cast<std::int32_t>(p + 1);
      telemetry.id_A = 0.01 * unit_noise(rng);
      telemetry.iq_A = iq_A + 0.01 * unit_noise(rng);
      telemetry.ud_V = -we_rad_per_s * motor.ls_H * iq_A + 0.2 * unit_noise(rng);
      telemetry.uq_V = motor.rs_ohm * iq_A + we_rad_per_s * motor.psi_Wb + 0.2 * unit_noise(rng);
      telemetry.speed_rpm = speed_rpm + unit_noise(rng);
      telemetry.rolling_counter = static_cast<std::int16_t>(tick % 16);
      telemetry.drive_state = ramping ? pumptherm::telemetry_t::DRIVE_STATE_ACCELERATING
                                      : pumptherm::telemetry_t::DRIVE_STATE_STEADY;
      telemetry.frame_sensor_degC = std::round((ambient_degC + 0.4 * rise_K) * 10.0) / 10.0;
      telemetry.ambient_degC = ambient_degC;
      telemetry.coolant_degC = kNaN;
      telemetry.dc_link_V = 48.0 + 0.1 * unit_noise(rng);
      telemetry.status_age_s = 0.05;
      Publish(lcm, PumpChannelName(options.prefix, pump, PumpChannel::kTelemetry), telemetry, sent,
              failures);

      if (!once_per_s) {
        continue;
      }
      pumptherm::temperatures_t temps;
      temps.utime = utime;
      temps.pump = pump;
      const double winding_degC = ambient_degC + rise_K;
      temps.resistance_ohm = motor.rs_ohm * (1.0 + 4.1e-3 * (winding_degC - 20.0));
      temps.resistance_sd_ohm = 0.002;
      temps.flux_Wb = motor.psi_Wb * (1.0 - 1e-3 * 0.6 * rise_K);
      temps.flux_sd_Wb = 5e-5;
      temps.winding_resistance_degC = winding_degC + 0.5 * unit_noise(rng);
      temps.winding_resistance_sd_K = 1.5;
      temps.magnet_flux_degC = ambient_degC + 0.6 * rise_K + 2.0 * unit_noise(rng);
      temps.magnet_flux_sd_K = 3.0;
      temps.ident_status = ramping ? pumptherm::temperatures_t::IDENT_CONVERGING
                                   : pumptherm::temperatures_t::IDENT_CONVERGED;
      temps.num_nodes = static_cast<std::int32_t>(options.nodes.size());
      for (std::size_t n = 0; n < options.nodes.size(); ++n) {
        const double share =
            0.4 + 0.6 * static_cast<double>(n) /
                      static_cast<double>(std::max<std::size_t>(1, options.nodes.size() - 1));
        temps.node_names.push_back(options.nodes[n]);
        temps.node_degC.push_back(ambient_degC + share * rise_K);
        temps.node_sd_K.push_back(0.3 + 0.2 * static_cast<double>(n));
      }
      temps.nis = std::pow(unit_noise(rng), 2);
      temps.filter_status = t_s < 30.0 ? pumptherm::temperatures_t::FILTER_CONVERGING
                                       : pumptherm::temperatures_t::FILTER_TRACKING;
      Publish(lcm, PumpChannelName(options.prefix, pump, PumpChannel::kTemperatures), temps, sent,
              failures);

      pumptherm::alarm_t alarm;
      alarm.utime = utime;
      alarm.pump = pump;
      alarm.time_to_trip_s = std::numeric_limits<double>::infinity();
      alarm.forecast_node = options.nodes.empty() ? "" : options.nodes.back();
      // The second pump shows a warning so that the spy displays a non-empty condition list.
      if (p == 1 && !options.nodes.empty()) {
        pumptherm::alarm_condition_t condition;
        condition.level = pumptherm::alarm_t::LEVEL_WARNING;
        condition.reason = pumptherm::alarm_condition_t::REASON_RATE_OF_RISE;
        condition.node = options.nodes.back();
        condition.value_degC = temps.node_degC.back();
        condition.threshold_degC = kNaN;
        condition.rate_K_per_s = 40.0 / 600.0 * std::exp(-t_s / 600.0);
        condition.since_utime = utime;
        condition.latched = false;
        alarm.conditions.push_back(condition);
        alarm.time_to_trip_s = 3600.0 - t_s;
      }
      alarm.num_conditions = static_cast<std::int32_t>(alarm.conditions.size());
      alarm.level = alarm.conditions.empty() ? pumptherm::alarm_t::LEVEL_NORMAL
                                             : pumptherm::alarm_t::LEVEL_WARNING;
      Publish(lcm, PumpChannelName(options.prefix, pump, PumpChannel::kAlarm), alarm, sent,
              failures);

      if (tick % std::max(1L, std::lround(options.clear_period_s * options.telemetry_rate_Hz)) ==
          0) {
        pumptherm::alarm_clear_t clear;
        clear.utime = utime;
        clear.pump = pump;
        clear.gateway = "pumptherm";
        clear.node = "";
        clear.key_id = "pumptherm-lcm-demo";
        clear.comment = "demo clear command";
        // Not signed (the demo holds no key): a gateway refuses it and counts it.
        clear.counter = tick;
        std::fill(std::begin(clear.tag), std::end(clear.tag), std::uint8_t{0});
        std::fill(std::begin(clear.signature), std::end(clear.signature), std::uint8_t{0});
        Publish(lcm, PumpChannelName(options.prefix, pump, PumpChannel::kAlarmClear), clear, sent,
                failures);
      }
    }

    if (once_per_s) {
      pumptherm::gateway_health_t health;
      health.utime = utime;
      health.uptime_s = t_s;
      health.num_pumps = static_cast<std::int32_t>(options.pumps.size());
      health.lcm_publish_failures = failures;
      health.clears_accepted = 0;
      health.clears_refused = 0;
      health.clears_unauthenticated = 0;
      health.mqtt_enabled = false;
      health.mqtt_connected = false;
      health.mqtt_dropped = 0;
      health.mqtt_alarms_dropped = 0;
      for (const char* name : {"can0", "can1"}) {
        pumptherm::interface_health_t interface;
        interface.name = name;
        interface.bus_state = pumptherm::interface_health_t::BUS_STATE_ERROR_ACTIVE;
        interface.rx_frames_per_s = 110.0 * static_cast<double>(options.pumps.size());
        interface.tx_frames_per_s = 10.0 * static_cast<double>(options.pumps.size());
        interface.rx_frames = std::lround(interface.rx_frames_per_s * t_s);
        interface.tx_frames = std::lround(interface.tx_frames_per_s * t_s);
        interface.rx_dropped = 0;
        interface.tx_dropped = 0;
        interface.rx_rejected = 0;
        interface.error_frames = 0;
        interface.reopens = 0;
        health.interfaces.push_back(interface);
      }
      health.num_interfaces = static_cast<std::int32_t>(health.interfaces.size());
      Publish(lcm, pumptherm::lcm_channels::GatewayHealthChannelName(options.prefix), health, sent,
              failures);
    }
  }

  for (const auto& [channel, count] : sent) {
    fmt::print("{} {}\n", channel, count);
  }
  if (failures > 0) {
    fmt::print(stderr, "pumptherm-lcm-demo: {} publishes failed\n", failures);
    return 1;
  }
  return 0;
}

}  // namespace

int main(int argc, char** argv) {
  CLI::App app{"Publish every pumptherm LCM type with made-up values (a demo, not estimates)"};
  app.footer(
      "Example (multicast on loopback only; run it in a network namespace, see docs/lcm.md):\n"
      "  pumptherm-lcm-demo --url 'udpm://239.255.76.67:7667?ttl=0' --duration-s 30\n"
      "Channels: PREFIX/<pump>/TELEMETRY, TEMPS, ALARM, ALARM_CLEAR; PREFIX/GATEWAY/HEALTH.\n"
      "Prints the number of messages per channel at the end.");
  Options options;
  // --url as in `pumptherm watch` and `clear-trip`; --lcm-url, its earlier name, still works.
  app.add_option("--url,--lcm-url", options.lcm_url,
                 "LCM URL (default: LCM_DEFAULT_URL or LCM's default)");
  app.add_option("--prefix", options.prefix, "channel prefix")->capture_default_str();
  app.add_option("--pumps", options.pumps, "pump names")->delimiter(',')->capture_default_str();
  app.add_option("--nodes", options.nodes, "thermal-network node names")
      ->delimiter(',')
      ->capture_default_str();
  app.add_option("--rate-hz", options.telemetry_rate_Hz,
                 "telemetry rate; the other types go at 1 Hz")
      ->check(CLI::Range(0.1, 1000.0))
      ->capture_default_str();
  app.add_option("--duration-s", options.duration_s,
                 "stop after this time; 0 runs until SIGINT/SIGTERM")
      ->check(CLI::NonNegativeNumber)
      ->capture_default_str();
  app.add_option("--clear-period-s", options.clear_period_s, "period of the alarm-clear command")
      ->check(CLI::PositiveNumber)
      ->capture_default_str();
  app.add_option("--seed", options.seed, "seed of the noise")->capture_default_str();
  try {
    app.parse(argc, argv);
  } catch (const CLI::ParseError& error) {
    const int code = app.exit(error);
    return code == 0 ? 0 : 2;
  }
  // Names become channel names: refuse bad ones before opening LCM (exit code 2).
  for (const std::string& pump : options.pumps) {
    if (!pumptherm::lcm_channels::IsValidPumpName(pump)) {
      fmt::print(stderr, "pumptherm-lcm-demo: --pumps: invalid pump name '{}'\n", pump);
      return 2;
    }
  }
  if (!pumptherm::lcm_channels::IsValidPrefix(options.prefix)) {
    fmt::print(stderr, "pumptherm-lcm-demo: --prefix: invalid channel prefix '{}'\n",
               options.prefix);
    return 2;
  }
  try {
    return Run(options);
  } catch (const std::exception& error) {
    fmt::print(stderr, "pumptherm-lcm-demo: {}\n", error.what());
    return 1;
  }
}
