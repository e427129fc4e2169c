// The fault matrix of the mismatch detector and the published virtual sensor (figures tool, not a
// test): tmp-generic (or `--model NAME`) truth, frame RTD only, each fault from `--fault-s` on.
// Prints a table and, with --json, one JSON object per case. docs/virtual-sensor.md, "Model
// mismatch".
#include <fmt/core.h>

#include <algorithm>
#include <cmath>
#include <cstdlib>
#include <sstream>
#include <string>
#include <utility>
#include <vector>

#include "tests/bench/mismatch_cases.hpp"

namespace mc = mismatch_cases;
namespace pe = pumptherm::estimators;

namespace {

std::string Named(const pe::MismatchFinding& f) {
  if (f.state != pe::MismatchState::kPlantChange &&
      f.state != pe::MismatchState::kSensorFaultSuspected) {
    return pe::MismatchStateName(f.state);
  }
  return fmt::format("{} {:.2f} (2nd {} l {:.0f}/{:.0f})", pe::MismatchEffectName(f.effect),
                     f.value, pe::MismatchEffectName(f.runner_up), f.likelihood_ratio,
                     f.runner_up_ratio);
}

/// "2,6,40" -> {2, 6, 40}.
std::vector<double> NumberList(const std::string& text) {
  std::vector<double> out;
  std::stringstream ss(text);
  std::string item;
  while (std::getline(ss, item, ',')) {
    if (!item.empty()) out.push_back(std::atof(item.c_str()));
  }
  return out;
}

/// The rotor-heat grid (--rotor-grid): every size, shape (a step, or a ramp over T), speed and
/// onset, each over `seeds` seeds.
struct RotorGrid {
  std::vector<double> heat_W{2.0, 6.0, 15.0, 40.0};
  std::vector<double> ramp_s{0.0, 600.0, 3600.0};
  std::vector<double> speed_rpm{21000.0, 15000.0, 10000.0};
  std::vector<double> onset_s{1800.0, 3600.0};
  double after_s = 7200.0;  ///< run on this long after the heat has reached its size
};

/// One grid point over the seeds: per node the lowest coverage after the onset, the largest
/// error after it and the largest sd; the longest detection delay (NaN: missed in some seed).
struct GridPoint {
  std::vector<std::string> nodes;
  std::vector<double> coverage, error_K, sd_K;
  double detect_s = 0.0;
};

GridPoint RunGridPoint(mc::CaseSpec spec, const pe::DisturbanceSensorConfig& dc, int seeds,
                       const std::string& dir) {
  GridPoint g;
  for (int seed = 1; seed <= seeds; ++seed) {
    spec.seed = static_cast<std::uint64_t>(seed);
    const mc::CaseResult r = mc::RunCase(spec, dir, {}, dc);
    if (g.nodes.empty()) {
      g.nodes = r.nodes;
      g.coverage.assign(g.nodes.size(), 1.0);
      g.error_K.assign(g.nodes.size(), 0.0);
      g.sd_K.assign(g.nodes.size(), 0.0);
    }
    for (std::size_t i = 0; i < g.nodes.size(); ++i) {
      g.coverage[i] = std::min(g.coverage[i], r.dist_coverage_after_fault[i]);
      g.error_K[i] = std::max(g.error_K[i], r.dist_max_error_after_fault_K[i]);
      g.sd_K[i] = std::max(g.sd_K[i], r.dist_max_sd_K[i]);
    }
    g.detect_s = std::max(g.detect_s, r.detect_delay_s);  // NaN stays NaN
    if (std::isnan(r.detect_delay_s)) g.detect_s = r.detect_delay_s;
  }
  return g;
}

/// Prints one line (or JSON object) per grid point: the disturbance filter's coverage of +-2 sd
/// after the onset (the lowest over the seeds), its largest error and sd, per node.
int RunGrid(const RotorGrid& grid, const mc::CaseSpec& base, const pe::DisturbanceSensorConfig& dc,
            int seeds, const std::string& dir, bool json) {
  if (!json) {
    fmt::print("{:>6} {:>7} {:>7} {:>7} {:>9} | {}\n", "heat_W", "ramp_s", "rpm", "onset_s",
               "detect_s",
               "per node: lowest coverage after the onset / largest error K / largest sd K");
  }
  double worst = 1.0;
  for (double speed : grid.speed_rpm) {
    for (double ramp : grid.ramp_s) {
      for (double heat : grid.heat_W) {
        for (double onset : grid.onset_s) {
          mc::CaseSpec spec = base;
          spec.fault = mc::Fault::kRotorHeat;
          spec.rotor_heat_W = heat;
          spec.rotor_heat_ramp_s = ramp;
          spec.speed_rpm = speed;
          spec.fault_s = onset;
          spec.duration_s = onset + ramp + grid.after_s;
          const GridPoint g = RunGridPoint(spec, dc, seeds, dir);
          std::string nodes;
          for (std::size_t i = 0; i < g.nodes.size(); ++i) {
            worst = std::min(worst, g.coverage[i]);
            nodes += json ? fmt::format(
                                "{}\"{}\": {{\"coverage_after\": {:.4f}, \"max_error_K\": "
                                "{:.3f}, \"max_sd_K\": {:.3f}}}",
                                i ? ", " : "", g.nodes[i], g.coverage[i], g.error_K[i], g.sd_K[i])
                          : fmt::format("{}{} {:.0f}%/{:.1f}/{:.1f}", i ? ", " : "", g.nodes[i],
                                        100.0 * g.coverage[i], g.error_K[i], g.sd_K[i]);
          }
          const std::string detect =
              std::isnan(g.detect_s) ? std::string("missed") : fmt::format("{:.0f}", g.detect_s);
          if (json) {
            fmt::print(
                "{{\"heat_W\": {}, \"ramp_s\": {}, \"speed_rpm\": {}, \"onset_s\": {}, "
                "\"seeds\": {}, \"detect_s\": \"{}\", \"nodes\": {{{}}}}}\n",
                heat, ramp, speed, onset, seeds, detect, nodes);
          } else {
            fmt::print("{:>6.0f} {:>7.0f} {:>7.0f} {:>7.0f} {:>9} | {}\n", heat, ramp, speed, onset,
                       detect, nodes);
          }
        }
      }
    }
  }
  if (!json) fmt::print("lowest coverage of any node in the grid: {:.1f} %\n", 100.0 * worst);
  return 0;
}

}  // namespace

int main(int argc, char** argv) {
  double duration_s = 10800.0, fault_s = 3600.0;
  int seeds = 1;
  bool json = false;
  double winding_sd_K = 0.0, magnet_sd_K = 0.0, magnet_bias_K = 2.0;
  pe::DisturbanceSensorConfig dc;
  mc::CaseSpec base;
  std::string cases = "none,cooling,rotor,losses,ambient,offset,stuck";
  bool grid = false;
  RotorGrid rotor_grid;
  for (int i = 1; i < argc; ++i) {
    const std::string a = argv[i];
    if (a == "--duration-s" && i + 1 < argc)
      duration_s = std::atof(argv[++i]);
    else if (a == "--fault-s" && i + 1 < argc)
      fault_s = std::atof(argv[++i]);
    else if (a == "--seeds" && i + 1 < argc)
      seeds = std::atoi(argv[++i]);
    else if (a == "--json")
      json = true;
    else if (a == "--model" && i + 1 < argc)
      base.model = argv[++i];
    else if (a == "--tables-dir" && i + 1 < argc)
      base.tables_dir = argv[++i];
    else if (a == "--speed-rpm" && i + 1 < argc)
      base.speed_rpm = std::atof(argv[++i]);
    else if (a == "--iq-max-A" && i + 1 < argc)
      base.iq_max_A = std::atof(argv[++i]);
    else if (a == "--restart-s" && i + 1 < argc)
      base.restart_s = std::atof(argv[++i]);
    else if (a == "--constant-iq-A" && i + 1 < argc)
      base.constant_iq_A = std::atof(argv[++i]);
    else if (a == "--rotor-loss-W" && i + 1 < argc)
      base.rotor_loss_W = std::atof(argv[++i]);
    else if (a == "--rotor-heat-W" && i + 1 < argc)
      base.rotor_heat_W = std::atof(argv[++i]);
    else if (a == "--rotor-heat-ramp-s" && i + 1 < argc)
      base.rotor_heat_ramp_s = std::atof(argv[++i]);
    else if (a == "--rotor-grid")
      grid = true;
    else if (a == "--no-inside-heat-bound")
      base.inside_heat_bound = false;
    else if (a == "--grid-heat-W" && i + 1 < argc)
      rotor_grid.heat_W = NumberList(argv[++i]);
    else if (a == "--grid-ramp-s" && i + 1 < argc)
      rotor_grid.ramp_s = NumberList(argv[++i]);
    else if (a == "--grid-speed-rpm" && i + 1 < argc)
      rotor_grid.speed_rpm = NumberList(argv[++i]);
    else if (a == "--grid-onset-s" && i + 1 < argc)
      rotor_grid.onset_s = NumberList(argv[++i]);
    else if (a == "--grid-after-s" && i + 1 < argc)
      rotor_grid.after_s = std::atof(argv[++i]);
    else if (a == "--cases" && i + 1 < argc)
      cases = "," + std::string(argv[++i]) + ",";
    else if (a == "--frame-heat-sd-W" && i + 1 < argc)
      dc.frame_heat_sd_W = std::atof(argv[++i]);
    else if (a == "--rotor-heat-sd-W" && i + 1 < argc)
      dc.rotor_heat_sd_W = std::atof(argv[++i]);
    else if (a == "--winding-sd-K" && i + 1 < argc)
      winding_sd_K = std::atof(argv[++i]);
    else if (a == "--magnet-sd-K" && i + 1 < argc)
      magnet_sd_K = std::atof(argv[++i]);
    else if (a == "--magnet-bias-K" && i + 1 < argc)
      magnet_bias_K = std::atof(argv[++i]);
    else if (a == "--magnet-bias-sd-K" && i + 1 < argc)
      dc.magnet_bias_sd_K = std::atof(argv[++i]);
    else if (a == "--rotor-heat-tau-s" && i + 1 < argc)
      dc.rotor_heat_tau_s = std::atof(argv[++i]);
    else if (a == "--loss-scale-sd" && i + 1 < argc)
      dc.loss_scale_sd = std::atof(argv[++i]);
    else if (a == "--loss-scale-max-sd" && i + 1 < argc)
      dc.loss_scale_max_sd = std::atof(argv[++i]);
    else if (a == "--sd-floor-K" && i + 1 < argc)
      dc.sd_floor_K = std::atof(argv[++i]);
    else if (a == "--node-process-sd-K" && i + 1 < argc)
      dc.node_process_sd_K = std::atof(argv[++i]);
    else if (a == "--ambient-ramp-s" && i + 1 < argc)
      base.ambient_ramp_s = std::atof(argv[++i]);
    else if (a == "--fit-ambient-ramp-s" && i + 1 < argc)
      base.fit_ambient_ramp_s = std::atof(argv[++i]);
    else if (a == "--sensor-step-gate-sd" && i + 1 < argc)
      dc.sensor_step_gate_sd = std::atof(argv[++i]);
    else {
      fmt::print(
          stderr,
          "usage: mismatch_matrix [--duration-s S] [--fault-s S] [--seeds N] [--json]\n"
          "  [--model NAME (a file NAME.toml of estimators/models)] [--tables-dir DIR (its tables' "
          "relative paths from)]\n"
          "  [--speed-rpm R (tmp-generic: 21000)] [--iq-max-A A] [--rotor-loss-W W (models other "
          "than tmp-generic)]\n"
          "  [--rotor-heat-W W] [--rotor-heat-ramp-s T (case rotorheat: W on the rotor, reached "
          "over T; 0: a step)]\n"
          "  [--rotor-grid (every size, ramp, speed and onset below; --seeds each)]\n"
          "  [--no-inside-heat-bound (the pump estimator without it, to compare)]\n"
          "  [--grid-heat-W 2,6,15,40] [--grid-ramp-s 0,600,3600] [--grid-speed-rpm "
          "21000,15000,10000]\n"
          "  [--grid-onset-s 1800,3600] [--grid-after-s 7200 (after the heat reached its size)]\n"
          "  [--constant-iq-A A (one load after the run-up; 0: steps every 10 min)]\n"
          "  [--restart-s S (restart the disturbance filter from its nodes alone at S)]\n"
          "  [--cases none,cooling,rotor,losses,ambient,offset,stuck,rotorheat]\n"
          "  [--frame-heat-sd-W W] [--rotor-heat-sd-W W] [--loss-scale-sd S] [--loss-scale-max-sd "
          "S] [--winding-sd-K K] "
          "[--sd-floor-K K] [--node-process-sd-K K]\n"
          "  [--magnet-sd-K K (emulated rotor reading: white sd)] [--magnet-bias-K K (its slow "
          "bias, sd)]\n"
          "  [--magnet-bias-sd-K K (the filter's bias state)] [--rotor-heat-tau-s S]\n"
          "  [--sensor-step-gate-sd G (0: off)] [--ambient-ramp-s S (the truth's; 0: a step)]\n"
          "  [--fit-ambient-ramp-s S (the detector's ramp hypothesis; 0: the step only)]\n");
      return 2;
    }
  }
  const std::string dir = std::string(PUMPTHERM_SOURCE_DIR) + "/estimators/models";
  if (grid) return RunGrid(rotor_grid, base, dc, seeds, dir, json);
  cases = "," + cases + ",";
  const std::pair<mc::Fault, const char*> faults[] = {
      {mc::Fault::kNone, "none"},           {mc::Fault::kCoolingLost, "cooling"},
      {mc::Fault::kRotorLoss, "rotor"},     {mc::Fault::kLosses40, "losses"},
      {mc::Fault::kAmbientRise, "ambient"}, {mc::Fault::kSensorOffset, "offset"},
      {mc::Fault::kSensorStuck, "stuck"},   {mc::Fault::kRotorHeat, "rotorheat"}};
  if (!json) {
    fmt::print("{:<36} {:>4} {:>9} {:>8} {:>8} {:<60} {:<60} {}\n", "case", "seed", "detect_s",
               "named_s", "right_s", "named first", "named at end",
               "false | max err K / coverage per node (published filter)");
  }
  for (const auto& [f, key] : faults) {
    if (cases.find("," + std::string(key) + ",") == std::string::npos) continue;
    if (base.model != "tmp-generic" && !mc::FaultAppliesToAnyModel(f)) {
      if (!json)
        fmt::print("{:<36} not made for {} (no effect scales every loss)\n", mc::FaultName(f),
                   base.model);
      continue;
    }
    for (int seed = 1; seed <= seeds; ++seed) {
      mc::CaseSpec spec = base;
      spec.fault = f;
      spec.fault_s = f == mc::Fault::kNone ? duration_s + 1.0 : fault_s;
      spec.duration_s = duration_s;
      spec.seed = static_cast<std::uint64_t>(seed);
      spec.winding_noise_sd_K = winding_sd_K;
      spec.magnet_noise_sd_K = magnet_sd_K;
      spec.magnet_bias_sd_K = magnet_bias_K;
      const mc::CaseResult r = mc::RunCase(spec, dir, {}, dc);
      std::string nodes;
      for (std::size_t i = 0; i < r.nodes.size(); ++i) {
        nodes += fmt::format("{}{} {:.2f}/{:.0f}%", i ? ", " : "", r.nodes[i], r.max_error_K[i],
                             100.0 * r.coverage[i]);
      }
      nodes += " | disturbance states:";
      for (std::size_t i = 0; i < r.nodes.size(); ++i) {
        nodes += fmt::format(" {} {:.2f}/{:.0f}%", r.nodes[i], r.dist_max_error_K[i],
                             100.0 * r.dist_coverage[i]);
      }
      nodes += fmt::format(", sensor steps {}, largest sd K:", r.dist_sensor_steps);
      for (std::size_t i = 0; i < r.nodes.size(); ++i)
        nodes += fmt::format(" {} {:.2f}", r.nodes[i], r.dist_max_sd_K[i]);
      if (json) {
        std::string jn;
        for (std::size_t i = 0; i < r.nodes.size(); ++i) {
          jn += fmt::format(
              "{}\"{}\": {{\"max_error_K\": {:.3f}, \"coverage\": {:.4f}, "
              "\"disturbance_max_error_K\": {:.3f}, \"disturbance_coverage\": {:.4f}, "
              "\"disturbance_max_sd_K\": {:.3f}}}",
              i ? ", " : "", r.nodes[i], r.max_error_K[i], r.coverage[i], r.dist_max_error_K[i],
              r.dist_coverage[i], r.dist_max_sd_K[i]);
        }
        fmt::print(
            "{{\"case\": \"{}\", \"seed\": {}, \"duration_s\": {}, \"fault_s\": {}, "
            "\"detect_delay_s\": {}, "
            "\"name_delay_s\": {}, \"right_from_s\": {}, \"named_first\": \"{}\", "
            "\"named_at_end\": \"{}\", "
            "\"expected\": \"{}\", "
            "\"false_alarms\": {}, \"sensor_steps\": {}, \"nodes\": {{{}}}}}\n",
            mc::FaultName(f), seed, duration_s, spec.fault_s,
            std::isnan(r.detect_delay_s) ? std::string("null")
                                         : fmt::format("{:.0f}", r.detect_delay_s),
            std::isnan(r.name_delay_s) ? std::string("null")
                                       : fmt::format("{:.0f}", r.name_delay_s),
            std::isnan(r.right_from_s) ? std::string("null")
                                       : fmt::format("{:.0f}", r.right_from_s),
            Named(r.at_naming), Named(r.at_end), pe::MismatchEffectName(mc::ExpectedEffect(f)),
            r.false_alarms, r.dist_sensor_steps, jn);
      } else {
        fmt::print(
            "{:<36} {:>4} {:>9} {:>8} {:>8} {:<60} {:<60} {} | {}\n", mc::FaultName(f), seed,
            std::isnan(r.detect_delay_s) ? std::string("-")
                                         : fmt::format("{:.0f}", r.detect_delay_s),
            std::isnan(r.name_delay_s) ? std::string("-") : fmt::format("{:.0f}", r.name_delay_s),
            std::isnan(r.right_from_s) ? std::string("-") : fmt::format("{:.0f}", r.right_from_s),
            std::isnan(r.name_delay_s) ? std::string("-") : Named(r.at_naming), Named(r.at_end),
            r.false_alarms, nodes);
      }
    }
  }
  return 0;
}
