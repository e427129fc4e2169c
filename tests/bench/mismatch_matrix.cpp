// The fault matrix of the mismatch detector and the published virtual sensor (figures tool, not a
// test): tmp-generic (or `--model NAME`) truth, frame RTD only, each fault from `--fault-s` on.
// Prints a table and, with --json, one JSON object per case. docs/virtual-sensor.md, "Model
// mismatch".
#include <fmt/core.h>

#include <cmath>
#include <cstdlib>
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

}  // namespace

int main(int argc, char** argv) {
  double duration_s = 10800.0, fault_s = 3600.0;
  int seeds = 1;
  bool json = false;
  double winding_sd_K = 0.0, magnet_sd_K = 0.0, magnet_bias_K = 2.0;
  pe::DisturbanceSensorConfig dc;
  mc::CaseSpec base;
  std::string cases = "none,cooling,rotor,losses,ambient,offset,stuck";
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
          "  [--speed-rpm R] [--iq-max-A A] [--rotor-loss-W W (models other than tmp-generic)]\n"
          "  [--constant-iq-A A (one load after the run-up; 0: steps every 10 min)]\n"
          "  [--restart-s S (restart the disturbance filter from its nodes alone at S)]\n"
          "  [--cases none,cooling,rotor,losses,ambient,offset,stuck]\n"
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
  cases = "," + cases + ",";
  const std::pair<mc::Fault, const char*> faults[] = {
      {mc::Fault::kNone, "none"},           {mc::Fault::kCoolingLost, "cooling"},
      {mc::Fault::kRotorLoss, "rotor"},     {mc::Fault::kLosses40, "losses"},
      {mc::Fault::kAmbientRise, "ambient"}, {mc::Fault::kSensorOffset, "offset"},
      {mc::Fault::kSensorStuck, "stuck"}};
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
