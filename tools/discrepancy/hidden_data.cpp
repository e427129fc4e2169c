#include "tools/discrepancy/hidden_data.hpp"

#include <cmath>
#include <random>
#include <stdexcept>

#include "estimators/thermal_model.hpp"
#include "tools/sim/sensor.hpp"
#include "tools/sim/thermal_plant.hpp"

namespace pumptherm::tools::discrepancy {

Data MakeHiddenEffectData(const HiddenDataConfig& c) {
  if (!(c.duration_s > 0.0) || !(c.step_s > 0.0) || c.step_s > c.duration_s)
    throw std::invalid_argument("hidden data: duration_s and step_s must be positive");
  std::vector<estimators::Effect> model_effects;
  for (const auto& e : c.hidden) {
    const estimators::EffectSpec* spec = estimators::FindEffect(e.name);
    if (spec != nullptr && !spec->sensor) model_effects.push_back(e);
  }
  const estimators::ThermalModel truth = estimators::ThermalModel::Parse(
      estimators::ApplyModelEffects(c.model_text, c.model_source, model_effects),
      c.model_source + " (truth)", c.files);
  std::vector<int> states;
  for (const std::string& n : c.measured_nodes) {
    const int i = truth.StateIndex(n);
    if (i < 0) throw std::invalid_argument("hidden data: '" + n + "' is not a state of the model");
    states.push_back(i);
  }

  // Load profile: its own random stream, so noise settings do not move it.
  std::mt19937_64 profile_rng(c.profile_seed);
  std::uniform_real_distribution<double> u01(0.0, 1.0);
  struct Segment {
    double end_s, speed_rpm, iq_A;
  };
  std::vector<Segment> segments;
  for (double t = 0.0; t < c.duration_s;) {
    t += c.segment_min_s + (c.segment_max_s - c.segment_min_s) * u01(profile_rng);
    const bool stop = u01(profile_rng) < 0.25;
    const double speed = stop ? 0.0 : c.max_speed_rpm * u01(profile_rng);
    const double iq = c.max_current_A * u01(profile_rng);
    segments.push_back({t, speed, iq});
  }
  const double phase = 2.0 * M_PI * u01(profile_rng);

  const double lsb_A = c.current_lsb_A > 0.0 ? c.current_lsb_A : 3.0 * c.max_current_A / 4096.0;
  sim::ThermalPlantConfig plant_config;
  plant_config.process_sd_K = c.process_sd_K;
  const Eigen::VectorXd x0 = Eigen::VectorXd::Constant(truth.StateCount(), c.ambient_degC);
  sim::ThermalPlant plant(truth, x0, plant_config, c.noise_seed);

  std::vector<sim::Sensor> sensors;
  for (std::size_t i = 0; i < states.size(); ++i) {
    sim::SensorConfig sc;
    sc.noise_sd = c.temperature_noise_K;
    sc.lsb = c.temperature_lsb_K;
    for (const auto& e : c.hidden) {
      if (e.node != c.measured_nodes[i] || e.values.empty()) continue;
      if (e.name == "sensor_lag") sc.lag_tau_s = e.values[0];
      if (e.name == "sensor_offset") sc.offset = e.values[0];
    }
    sensors.emplace_back(sc, c.noise_seed * 1000003u + i + 1);
  }
  sim::SensorConfig ambient_sc;
  ambient_sc.noise_sd = c.temperature_noise_K;
  ambient_sc.lsb = c.temperature_lsb_K;
  sim::Sensor ambient_sensor(ambient_sc, c.noise_seed * 7919u + 11);
  std::mt19937_64 noise(c.noise_seed + 99);
  std::normal_distribution<double> normal(0.0, 1.0);

  Data d;
  d.source = "hidden-effect data";
  for (const std::string& n : c.measured_nodes) d.measured.push_back({n, {}});
  const auto steps = static_cast<std::size_t>(std::floor(c.duration_s / c.step_s + 1e-9)) + 1;
  std::size_t seg = 0;
  estimators::ThermalInputs in, previous;
  for (std::size_t k = 0; k < steps; ++k) {
    const double t = static_cast<double>(k) * c.step_s;
    while (seg + 1 < segments.size() && t >= segments[seg].end_s) ++seg;
    in.speed_rpm = segments[seg].speed_rpm;
    in.id_A = 0.0;
    in.iq_A = segments[seg].iq_A;
    in.ambient_degC =
        c.ambient_degC + c.ambient_drift_K * std::sin(2.0 * M_PI * t / 86400.0 + phase);
    in.coolant_degC = c.coolant_degC;
    // The sample at t reports the inputs that act from t on (zero-order hold, as `simulate`):
    // the step that ends at t ran with the previous sample's inputs.
    if (k > 0) plant.Step(previous, c.step_s);
    previous = in;
    d.time_s.push_back(t);
    d.speed_rpm.push_back(in.speed_rpm + c.speed_noise_rpm * normal(noise));
    d.id_A.push_back(sim::Quantise(c.current_noise_A * normal(noise), lsb_A, -1e9, 1e9));
    d.iq_A.push_back(sim::Quantise(in.iq_A + c.current_noise_A * normal(noise), lsb_A, -1e9, 1e9));
    d.ambient_degC.push_back(ambient_sensor.Measure(in.ambient_degC, c.step_s));
    d.coolant_degC.push_back(c.coolant_degC);
    for (std::size_t i = 0; i < states.size(); ++i)
      d.measured[i].value_degC.push_back(
          sensors[i].Measure(plant.State_degC()(states[i]), c.step_s));
  }
  return d;
}

}  // namespace pumptherm::tools::discrepancy
