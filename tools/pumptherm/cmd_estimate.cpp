// pumptherm estimate: the virtual thermal sensor (Kalman filter on the thermal network) over
// recorded inputs and measured node temperatures; as in the daemon, optionally the
// disturbance-state filter, and the mismatch detector's verdict per row.
#include <fmt/core.h>

#include <algorithm>
#include <cmath>
#include <optional>
#include <sstream>

#include "estimators/disturbance_sensor.hpp"
#include "estimators/kalman_virtual_sensor.hpp"
#include "estimators/mismatch_detector.hpp"
#include "tools/common/csv.hpp"
#include "tools/common/thermal_input_series.hpp"
#include "tools/pumptherm/model_files.hpp"
#include "tools/pumptherm/recording.hpp"
#include "tools/pumptherm/subcommand.hpp"
#include "tools/pumptherm/thermal_columns.hpp"

namespace pumptherm::tools {
namespace {

struct EstimateOptions {
  std::string model;
  std::string input;
  std::string output = "-";
  std::string measure = "frame";
  std::string winding_column;
  std::string magnet_column;
  std::string magnet_node = "rotor";
  double magnet_sd_K = 3.0;
  double initial_degC = std::nan("");
  std::string initial = "measured";
  std::string columns;      ///< column preset ("" or "paderborn")
  double max_step_s = 0.0;  ///< 0: one step per row
  std::string interpolation = "hold";
  RecordingSource recording;  ///< --log: the inputs from a candump recording instead of --input
  bool disturbance_states = false;  ///< write the disturbance-state filter's nodes and sds
  double sensor_lag_s =
      0.0;  ///< the measured sensor's first-order lag (detector, disturbance filter)
  estimators::VirtualSensorConfig config;
};

int RunEstimate(EstimateOptions& o) {
  const estimators::ThermalModel model = LoadThermalModel(o.model);
  o.config.measured_nodes.clear();
  {
    std::stringstream ss(o.measure);
    std::string node;
    while (std::getline(ss, node, ',')) {
      if (node.empty()) continue;
      if (model.StateIndex(node) < 0) {
        throw InputError(fmt::format(
            "--measure: '{}' is not a node with heat capacity of model '{}'", node, model.Name()));
      }
      o.config.measured_nodes.push_back(node);
    }
  }
  ThermalInputSeries series;
  std::vector<double> winding, magnet;
  std::vector<std::vector<double>> measured;
  Eigen::VectorXd x_first;
  if (o.interpolation != "hold" && o.interpolation != "linear") {
    throw InputError(fmt::format("--inputs: '{}' is neither 'hold' nor 'linear'", o.interpolation));
  }
  if (!(o.max_step_s >= 0.0) || !std::isfinite(o.max_step_s)) {
    throw InputError("--max-step-s: must be a finite number >= 0");
  }
  if (o.initial != "measured" && o.initial != "first-row") {
    throw InputError(
        fmt::format("--initial: '{}' is neither 'measured' nor 'first-row'", o.initial));
  }
  try {
    if (o.input.empty() == o.recording.log.empty())
      throw InputError("give --input CSV or --log RECORDING");
    const CsvTable csv =
        o.input.empty() ? CsvTable::Parse(RecordingToCsv(o.recording, nullptr), o.recording.log)
                        : CsvTable::Read(o.input);
    series = ReadThermalInputs(
        csv, {[&](const std::string& standard) { return InputColumn(o.columns, standard); },
              model.UsesCoolant()});
    for (const auto& node : o.config.measured_nodes) {
      measured.push_back(csv.ColumnAllowingNaN(InputColumn(o.columns, node + "_C")));
    }
    if (series.size() > 0 && o.initial == "first-row" && std::isnan(o.initial_degC)) {
      x_first = InitialTemperatures_degC(model, csv, o.columns, o.initial, o.initial_degC,
                                         series.ambient_degC[0]);
    }
    if (!o.winding_column.empty()) winding = csv.ColumnAllowingNaN(o.winding_column);
    if (!o.magnet_column.empty()) magnet = csv.ColumnAllowingNaN(o.magnet_column);
  } catch (const CsvError& e) {
    throw InputError(e.what());
  }
  const std::vector<double>& t = series.time_s;
  if (t.empty())
    throw InputError(fmt::format("{}: no data rows", o.input.empty() ? o.recording.log : o.input));
  const int magnet_state = magnet.empty() ? -1 : model.StateIndex(o.magnet_node);
  if (!magnet.empty() && magnet_state < 0) {
    throw InputError(
        fmt::format("--magnet-node: '{}' is not a node with heat capacity of model '{}'",
                    o.magnet_node, model.Name()));
  }
  if (!(o.magnet_sd_K > 0.0) || !std::isfinite(o.magnet_sd_K)) {
    throw InputError("--magnet-sd-K: must be a positive finite number");
  }
  if (!(o.sensor_lag_s >= 0.0) || !std::isfinite(o.sensor_lag_s)) {
    throw InputError("--sensor-lag-s: must be a finite number >= 0");
  }
  // The detector and the disturbance-state filter read one sensor, as the daemon's frame sensor.
  const bool one_sensor = o.config.measured_nodes.size() == 1;
  if (o.disturbance_states && !one_sensor) {
    throw InputError("--disturbance-states: give exactly one node to --measure");
  }
  if (o.disturbance_states && !winding.empty()) {
    throw InputError(
        "--disturbance-states: the winding from resistance is not fused into it (as in the "
        "daemon); leave out --winding-column");
  }
  // Inputs a fraction w of the way from row k-1 to row k (held at row k-1 unless linear).
  const bool linear = o.interpolation == "linear";
  auto between = [&](std::size_t k, double w) { return series.Between(k, w, linear); };
  estimators::VirtualThermalSensor vts(model, o.config);
  const int n = model.StateCount();
  const std::size_t m = measured.size();
  // Unknown initial temperatures: the mean of the first measured values (else the first
  // ambient), with the large initial covariance of the configuration.
  double x0 = o.initial_degC;
  if (std::isnan(x0)) {
    double sum = 0.0;
    int count = 0;
    for (const auto& col : measured) {
      if (std::isfinite(col[0])) {
        sum += col[0];
        ++count;
      }
    }
    x0 = count > 0 ? sum / count : series.ambient_degC[0];
  }
  vts.Initialise(x_first.size() == n ? x_first : Eigen::VectorXd::Constant(n, x0));

  // The daemon's disturbance-state filter (pump[].disturbance_states) and mismatch detector, on
  // the one measured node; the magnet column as the daemon's magnet from the flux: white sd at
  // its least, --magnet-sd-K the sd of its slow bias (the daemon's magnet_min_sd_K).
  std::optional<estimators::DisturbanceThermalSensor> dist;
  std::optional<estimators::MismatchDetector> detector;
  double dist_floor_K = 0.0;
  if (one_sensor) {
    const std::string& node = o.config.measured_nodes[0];
    estimators::MismatchDetectorConfig mc;
    mc.measured_node = node;
    mc.measurement_sd_K = o.config.measurement_sd_K;
    mc.sensor_lag_s = o.sensor_lag_s;
    mc.rotor_node = o.magnet_node;
    if (!magnet.empty()) mc.magnet_node = o.magnet_node;
    detector.emplace(model, mc);
    detector->Initialise(std::isfinite(measured[0][0]) ? measured[0][0] : x0, t[0]);
  }
  if (o.disturbance_states) {
    estimators::DisturbanceSensorConfig dc;
    dc.measured_node = o.config.measured_nodes[0];
    dc.measurement_sd_K = o.config.measurement_sd_K;
    dc.sensor_lag_s = o.sensor_lag_s;
    dc.rotor_node = o.magnet_node;
    dc.initial_sd_K = o.config.initial_sd_K;
    dc.initial_spread_sd_K = o.config.initial_spread_sd_K;
    if (!magnet.empty()) dc.magnet_node = o.magnet_node;
    dc.magnet_bias_sd_K = o.magnet_sd_K;
    dist.emplace(model, dc);
    dist_floor_K = dc.sd_floor_K;
    dist->Initialise(std::isfinite(measured[0][0]) ? measured[0][0] : x0);
  }

  std::vector<std::string> columns{"time_s"};
  for (const auto& node : model.Nodes()) columns.push_back(node.name + "_C");
  for (const auto& node : model.Nodes()) columns.push_back(node.name + "_sd_K");
  for (const auto& node : o.config.measured_nodes) columns.push_back(node + "_innovation_K");
  if (!winding.empty()) columns.push_back("winding_innovation_K");
  if (!magnet.empty()) columns.push_back("magnet_innovation_K");
  columns.push_back("nis");
  if (o.disturbance_states) columns.push_back("frame_sensor_offset_K");  // as the daemon's CSV
  const std::size_t numeric_columns = columns.size();
  if (detector) {
    for (const char* c : {"mismatch_state", "mismatch_effect", "mismatch_value"})
      columns.push_back(c);
  }
  CsvWriter out(o.output, columns);
  std::vector<double> row(numeric_columns);
  std::vector<std::string> text(columns.size() - numeric_columns);
  Eigen::VectorXd y(static_cast<Eigen::Index>(m));
  const Eigen::VectorXd no_measurement =
      Eigen::VectorXd::Constant(static_cast<Eigen::Index>(m), std::nan(""));
  const estimators::NodeMeasurements none;
  estimators::NodeMeasurements extra;
  for (std::size_t k = 0; k < t.size(); ++k) {
    for (std::size_t j = 0; j < m; ++j) y(static_cast<Eigen::Index>(j)) = measured[j][k];
    const double w = winding.empty() ? std::nan("") : winding[k];
    const double mag = magnet.empty() ? std::nan("") : magnet[k];
    extra.Clear();
    extra.Add(estimators::kWindingWeightsRow, w, o.config.winding_measurement_sd_K);
    if (!magnet.empty()) extra.Add(magnet_state, mag, o.magnet_sd_K);
    estimators::KalmanUpdateReport rep;
    if (k > 0) {
      // Rows further apart than --max-step-s are split; the measurements enter at the row.
      const double dt_s = t[k] - t[k - 1];
      const int steps = o.max_step_s > 0.0
                            ? std::max(1, static_cast<int>(std::ceil(dt_s / o.max_step_s - 1e-9)))
                            : 1;
      estimators::DisturbanceReadings readings;
      for (int j = 0; j + 1 < steps; ++j) {
        const estimators::ThermalInputs held = between(k, static_cast<double>(j) / steps);
        vts.Step(held, dt_s / steps, no_measurement, none);
        if (dist) dist->Step(held, dt_s / steps, readings);
        if (detector)
          detector->Step(held, dt_s / steps, std::nan(""), t[k - 1] + dt_s * (j + 1) / steps);
      }
      const estimators::ThermalInputs held = between(k, static_cast<double>(steps - 1) / steps);
      rep = vts.Step(held, dt_s / steps, y, extra);
      if (rep.refused) {
        throw InputError(fmt::format("{}: data row {} (time_s {}): the inputs are not finite",
                                     o.input.empty() ? o.recording.log : o.input, k + 1, t[k]));
      }
      if (rep.rejected_measurements > 0) {
        throw InputError(
            fmt::format("data row {} (time_s {}): a winding or magnet reading with an sd that is "
                        "not positive and finite",
                        k + 1, t[k]));
      }
      if (dist) {
        // Readings on consecutive rows of a split row are consecutive readings: the step test
        // of the sensor's offset compares them over the steps between (the daemon's steps have
        // a reading each).
        if (steps > 1 && std::isfinite(measured[0][k - 1])) dist->ReopenSensorOffset();
        readings.frame_degC = measured[0][k];
        readings.magnet_degC = mag;  // no sd of its own: the filter's least white sd
        dist->Step(held, dt_s / steps, readings);
      }
      if (detector) detector->Step(held, dt_s / steps, measured[0][k], t[k], mag);
    }
    const estimators::ThermalInputs in = series.Inputs(k);
    Eigen::VectorXd x_est = vts.Estimate_degC();
    Eigen::MatrixXd cov = vts.Covariance_K2();
    if (dist) {
      // The node block of its covariance with the floor on every node's variance, as it reports.
      x_est = dist->Filter().State().head(n);
      cov = dist->Filter().Covariance().topLeftCorner(n, n);
      cov.diagonal().array() += dist_floor_K * dist_floor_K;
    }
    const Eigen::VectorXd all = model.AllTemperatures_degC(in, x_est);
    const Eigen::MatrixXd jac = model.AllTemperatureJacobian(in);
    const Eigen::VectorXd var = (jac * cov * jac.transpose()).diagonal();
    std::size_t c = 0;
    row[c++] = t[k];
    for (Eigen::Index i = 0; i < all.size(); ++i) row[c++] = all(i);
    for (Eigen::Index i = 0; i < all.size(); ++i) row[c++] = std::sqrt(std::max(var(i), 0.0));
    // Innovations in the order the filter stacked them (valid measurements only).
    Eigen::Index r = 0;
    for (std::size_t j = 0; j < m; ++j) {
      const bool valid = k > 0 && std::isfinite(measured[j][k]);
      row[c++] = valid ? rep.innovation(r++) : std::nan("");
    }
    // The winding row is stacked only when the model has a winding (WindingWeights).
    if (!winding.empty()) {
      const bool valid = k > 0 && std::isfinite(w) && model.WindingWeights().sum() > 0.0 &&
                         r < rep.innovation.size();
      row[c++] = valid ? rep.innovation(r++) : std::nan("");
    }
    if (!magnet.empty()) {
      const bool valid = k > 0 && std::isfinite(mag) && r < rep.innovation.size();
      row[c++] = valid ? rep.innovation(r++) : std::nan("");
    }
    row[c++] = k > 0 && rep.measurements > 0 ? rep.nis : std::nan("");
    if (dist) row[c++] = dist->SensorOffset_K();
    if (detector) {
      const estimators::MismatchFinding& f = detector->Finding();
      text[0] = estimators::MismatchStateName(f.state);
      text[1] = estimators::MismatchEffectName(f.effect);
      text[2] = std::isnan(f.value) ? "nan" : fmt::format("{}", f.value);
    }
    out.Row(row, text);
  }
  out.Close();
  return 0;
}

const SubcommandRegistrar kRegistrar{
    "estimate", "Virtual thermal sensor: Kalman filter on a thermal model over recorded data",
    [](CLI::App& app) -> std::function<int()> {
      auto o = std::make_shared<EstimateOptions>();
      app.add_option("--model,-m", o->model, "Shipped model name or path to a model .toml")
          ->required();
      app.add_option(
          "--input,-i", o->input,
          "CSV with time_s, speed_rpm, id_A, iq_A, ambient_C (coolant_C if the model has "
          "a coolant) and <node>_C for every measured node (empty or nan = not measured); or "
          "--log");
      AddRecordingOptions(app, o->recording);
      app.add_option("--motor", o->recording.motor,
                     "with --log: motor preset or file (pole pairs for the speed)")
          ->capture_default_str();
      app.add_option(
          "--output,-o", o->output,
          "CSV to write: <node>_C and <node>_sd_K per node, innovations (of the standard "
          "filter), nis and, with one --measure node, the mismatch detector's "
          "mismatch_state, mismatch_effect, mismatch_value (as the daemon's CSV; with "
          "--disturbance-states also frame_sensor_offset_K)");
      app.add_option("--measure", o->measure, "Measured nodes, comma-separated")
          ->capture_default_str();
      app.add_option("--winding-column", o->winding_column,
                     "Column with the winding temperature from resistance identification, degC");
      app.add_option(
          "--magnet-column", o->magnet_column,
          "Column with the magnet temperature from the identified flux, degC (the daemon's "
          "magnet_flux_C), fused as a measurement of --magnet-node");
      app.add_option("--magnet-node", o->magnet_node,
                     "Node the magnet temperature measures; also the rotor of the disturbance "
                     "filter's rotor heat and of the detector's rotor-loss hypothesis")
          ->capture_default_str();
      app.add_option("--magnet-sd-K", o->magnet_sd_K, "Noise of the flux-based magnet temperature")
          ->capture_default_str();
      app.add_option("--measurement-sd-K", o->config.measurement_sd_K,
                     "Node sensor noise (Saheba 2010 eq. 38)")
          ->capture_default_str();
      app.add_option("--process-sd-K", o->config.process_sd_K,
                     "Process noise per state per second (eq. 39)")
          ->capture_default_str();
      app.add_option("--winding-sd-K", o->config.winding_measurement_sd_K,
                     "Noise of the resistance-based winding temperature")
          ->capture_default_str();
      app.add_option("--initial-sd-K", o->config.initial_sd_K,
                     "Initial uncertainty common to all nodes")
          ->capture_default_str();
      app.add_option("--initial-spread-sd-K", o->config.initial_spread_sd_K,
                     "Initial uncertainty of each node on its own")
          ->capture_default_str();
      app.add_option("--initial-C", o->initial_degC,
                     "Initial estimate of every node, degC (overrides --initial)");
      app.add_option(
             "--initial", o->initial,
             "Initial estimate: 'measured' (every node at the mean of the first measured "
             "values) or 'first-row' (each node at its <node>_C of the first row, measured "
             "or not: a known start); the initial covariance is the configured one either way")
          ->capture_default_str();
      app.add_flag(
          "--disturbance-states", o->disturbance_states,
          "Write the disturbance-state filter's nodes and sds (the daemon's "
          "pump[].disturbance_states: frame-path and rotor heat, loss scale, sensor lag and "
          "offset; the magnet column with a slow-bias state of sd --magnet-sd-K) instead of "
          "the standard filter's; one --measure node, no --winding-column");
      app.add_option(
             "--sensor-lag-s", o->sensor_lag_s,
             "First-order lag of the measured sensor, s (the daemon's frame_sensor_lag_s): a "
             "state of the disturbance filter and of the mismatch detector")
          ->capture_default_str();
      app.add_option(
          "--columns", o->columns,
          "Column names of a known data set: 'paderborn' (motor_speed, i_d, i_q, ambient, "
          "coolant, <node>)");
      app.add_option("--max-step-s", o->max_step_s,
                     "Longest filter step, s; rows further apart are split and the measurements "
                     "enter at the rows (0 = one step per row)")
          ->capture_default_str();
      app.add_option("--inputs", o->interpolation,
                     "Inputs between rows: 'hold' (the earlier row's) or 'linear' (interpolated at "
                     "the start of each step)")
          ->capture_default_str();
      app.footer(
          "Example:\n  pumptherm estimate --model saheba2010-improved --input measured.csv "
          "--measure frame --output est.csv\n"
          "  pumptherm estimate --model tests/data/models/wallscheid2017-4node.toml --columns "
          "paderborn --measure "
          "stator_yoke --input profile46.csv");
      return [o] { return RunEstimate(*o); };
    }};

}  // namespace
}  // namespace pumptherm::tools
