// pumptherm estimate: the daemon's pump estimator (estimators/pump_estimator.hpp) over a
// recording or a CSV, with the daemon's settings for that model (or a pump of its configuration
// file), writing the daemon's CSV; or, with --paper-filter, the virtual thermal sensor of Saheba
// et al. 2010 alone over a CSV (any nodes measured).
#include <fmt/core.h>

#include <algorithm>
#include <cmath>
#include <fstream>
#include <iostream>
#include <iterator>
#include <limits>
#include <optional>
#include <sstream>
#include <vector>

#include "daemon/config.hpp"
#include "daemon/gateway.hpp"
#include "daemon/offline.hpp"
#include "daemon/published_fields.hpp"
#include "daemon/resources.hpp"
#include "estimators/kalman_virtual_sensor.hpp"
#include "estimators/pump_estimator.hpp"
#include "protocol/candump_log.hpp"
#include "tools/common/csv.hpp"
#include "tools/common/thermal_input_series.hpp"
#include "tools/pumptherm/model_files.hpp"
#include "tools/pumptherm/recording.hpp"
#include "tools/pumptherm/recording_pump.hpp"
#include "tools/pumptherm/subcommand.hpp"
#include "tools/pumptherm/thermal_columns.hpp"

namespace pumptherm::tools {
namespace {

struct EstimateOptions {
  std::string config;  ///< the daemon's configuration file (with --pump)
  std::string pump;
  std::string model = "tmp-generic";
  std::string input;
  std::string output = "-";
  std::string measure = "frame";
  std::string magnet_node;
  double sensor_lag_s = 0.0;
  std::string filter = "auto";  ///< auto (what the daemon ships), disturbance, standard
  double thermal_period_s = 1.0;
  /// --log: subtracted from the Unix time in time_s (NaN: the recording's first whole second).
  double csv_time_origin_s = std::numeric_limits<double>::quiet_NaN();
  RecordingSource recording;  ///< --log: a candump recording
  // The CSV's columns and steps.
  std::string columns;
  double max_step_s = 0.0;
  std::string interpolation = "hold";
  std::string winding_column;
  // The paper's filter alone (--paper-filter): Saheba et al. 2010, any nodes measured.
  bool paper_filter = false;
  std::string magnet_column;
  double magnet_sd_K = 3.0;
  double initial_degC = std::nan("");
  std::string initial = "measured";
  estimators::VirtualSensorConfig paper;
  std::vector<CLI::Option*> paper_only;  ///< options that only --paper-filter takes
};

// ---------------------------------------------------------------------------------------------
// The pump as the daemon configures it.

/// The settings the daemon ships for a pump of `o.model` (daemon::PumpConfig's defaults), with
/// what a user would change on the command line.
daemon::PumpConfig DefaultPump(const EstimateOptions& o) {
  daemon::PumpConfig p;
  p.name = "pump";
  p.thermal_model = o.model;
  p.motor = o.recording.motor;
  p.node_id = o.recording.node_id;
  p.measured_node = o.measure;
  p.magnet_node = o.magnet_node;
  p.frame_sensor_lag_s = o.sensor_lag_s;
  if (o.filter != "auto") {
    p.disturbance_states_explicit = true;
    p.disturbance_states = o.filter == "disturbance";
  }
  return p;
}

// ---------------------------------------------------------------------------------------------
// A recording: the daemon's own pipeline for that one pump.

int RunRecording(const EstimateOptions& o) {
  PumpRecordingRun run;
  run.config = o.config;
  run.config_pump = o.pump;
  run.pump = DefaultPump(o);
  run.thermal_period_s = o.thermal_period_s;
  run.recording = o.recording;
  run.csv_time_origin_s = o.csv_time_origin_s;
  run.csv_file = o.output;
  RunPumpOnRecording(run);
  return 0;
}

// ---------------------------------------------------------------------------------------------
// A CSV: the pump estimator row by row.

struct CsvData {
  ThermalInputSeries series;
  std::vector<std::vector<double>> measured;  ///< per --measure node
  std::vector<double> winding, magnet;
  Eigen::VectorXd x_first;
};

std::vector<std::string> MeasuredNodes(const std::string& measure,
                                       const estimators::ThermalModel& model) {
  std::vector<std::string> nodes;
  std::stringstream ss(measure);
  std::string node;
  while (std::getline(ss, node, ',')) {
    if (node.empty()) continue;
    if (model.StateIndex(node) < 0) {
      throw InputError(fmt::format("--measure: '{}' is not a node with heat capacity of model '{}'",
                                   node, model.Name()));
    }
    nodes.push_back(node);
  }
  if (nodes.empty()) throw InputError("--measure: name at least one node");
  return nodes;
}

CsvData ReadCsv(const EstimateOptions& o, const estimators::ThermalModel& model,
                const std::vector<std::string>& nodes) {
  CsvData d;
  try {
    const CsvTable csv = CsvTable::Read(o.input);
    d.series = ReadThermalInputs(
        csv, {[&](const std::string& standard) { return InputColumn(o.columns, standard); },
              model.UsesCoolant()});
    for (const auto& node : nodes)
      d.measured.push_back(csv.ColumnAllowingNaN(InputColumn(o.columns, node + "_degC")));
    if (!o.winding_column.empty()) d.winding = csv.ColumnAllowingNaN(o.winding_column);
    if (!o.magnet_column.empty()) d.magnet = csv.ColumnAllowingNaN(o.magnet_column);
    if (d.series.size() > 0 && o.paper_filter && o.initial == "first-row" &&
        std::isnan(o.initial_degC)) {
      d.x_first = InitialTemperatures_degC(model, csv, o.columns, o.initial, o.initial_degC,
                                           d.series.ambient_degC[0]);
    }
  } catch (const CsvError& e) {
    throw InputError(e.what());
  }
  if (d.series.size() < 2) throw InputError(fmt::format("{}: needs two data rows", o.input));
  return d;
}

/// Steps of row k (rows further apart than --max-step-s are split).
int StepsOfRow(const EstimateOptions& o, double dt_s) {
  return o.max_step_s > 0.0 ? std::max(1, static_cast<int>(std::ceil(dt_s / o.max_step_s - 1e-9)))
                            : 1;
}

/// The pump: the configuration's (with its thermal period), or the daemon's defaults for the
/// model.
daemon::PumpConfig ResolvePump(const EstimateOptions& o, double& period_s) {
  period_s = o.thermal_period_s;
  if (o.config.empty()) return DefaultPump(o);
  const daemon::DaemonConfig c = ConfigWithPump(o.config, o.pump);
  period_s = c.gateway.thermal_period_s;
  daemon::PumpConfig pump = c.pumps.front();
  // Files named in the configuration are found from its folder, as the daemon finds them.
  try {
    if (estimators::MotorPresetText(pump.motor).empty())
      pump.motor =
          daemon::ResolveResource(daemon::ResourceKind::kMotor, pump.motor, c.dbc.base_dir);
    pump.thermal_model =
        daemon::ResolveResource(daemon::ResourceKind::kModel, pump.thermal_model, c.dbc.base_dir);
  } catch (const std::exception& e) {
    throw InputError(fmt::format("{}: pump {}: {}", o.config, pump.name, e.what()));
  }
  return pump;
}

/// The pump's estimator settings. A CSV's readings are as fresh as its rows: without a
/// configuration, the ages the alarms allow are at least two row spacings (else every step
/// between rows would find the sensor missing).
estimators::PumpEstimatorConfig CsvEstimatorConfig(const EstimateOptions& o,
                                                   const ThermalInputSeries& series,
                                                   const daemon::PumpConfig& pump,
                                                   double period_s) {
  estimators::PumpEstimatorConfig e = daemon::EstimatorConfig(pump, period_s);
  double largest_dt_s = 0.0;
  for (std::size_t k = 1; k < series.size(); ++k)
    largest_dt_s = std::max(largest_dt_s, series.time_s[k] - series.time_s[k - 1]);
  if (o.config.empty())
    e.alarms.stale_after_s = std::max(e.alarms.stale_after_s, 2.0 * largest_dt_s);
  return e;
}

/// The winding column as the identifier's tracking output at this row (NaN: none).
estimators::IdentifierOutput WindingReading(const CsvData& d, std::size_t k) {
  estimators::IdentifierOutput id;
  if (d.winding.empty() || !std::isfinite(d.winding[k])) return id;
  id.estimate.status = estimators::ResistanceStatus::kTracking;
  id.estimate.winding_degC = d.winding[k];
  id.estimate.winding_sd_K = 0.0;
  id.sample_age_s = 0.0;
  return id;
}

int RunCsvEstimator(const EstimateOptions& o) {
  double period_s = 1.0;
  const daemon::PumpConfig pump = ResolvePump(o, period_s);
  const estimators::ThermalModel model = LoadThermalModel(pump.thermal_model);
  const estimators::MotorDescription motor = LoadMotor(pump.motor);
  const std::vector<std::string> nodes = MeasuredNodes(pump.measured_node, model);
  if (nodes.size() != 1) {
    throw InputError(
        "--measure: the pump estimator reads one frame sensor (--paper-filter "
        "measures several nodes)");
  }
  const CsvData d = ReadCsv(o, model, nodes);
  std::unique_ptr<estimators::PumpEstimator> est;
  try {
    est = std::make_unique<estimators::PumpEstimator>(
        CsvEstimatorConfig(o, d.series, pump, period_s), motor, model);
  } catch (const std::invalid_argument& e) {
    throw InputError(e.what());
  }
  std::ofstream file;
  std::ostream& out = o.output == "-" ? std::cout : (file.open(o.output), file);
  if (!out) throw InputError(fmt::format("--output {}: cannot create", o.output));
  std::string line = "time_s";
  for (const auto& n : model.StateNames()) line += fmt::format(",{}_degC,{}_sd_K", n, n);
  out << line << daemon::CsvHeader() << '\n';
  const bool linear = o.interpolation == "linear";
  const auto& t = d.series.time_s;
  daemon::FieldSource source;
  source.estimate = &est->estimate();
  source.model = &model;
  source.nis_limit = pump.alarms.monitor.nis_limit;
  for (std::size_t k = 1; k < t.size(); ++k) {
    const double dt_s = t[k] - t[k - 1];
    const int steps = StepsOfRow(o, dt_s);
    for (int j = 1; j <= steps; ++j) {
      estimators::PumpPeriod p;
      p.end_us = static_cast<std::int64_t>(std::llround((t[k - 1] + dt_s * j / steps) * 1e6));
      p.dt_s = dt_s / steps;
      p.inputs = d.series.Between(k, static_cast<double>(j - 1) / steps, linear);
      p.fresh_inputs = true;
      p.mean_iq_A = p.inputs.iq_A;
      p.ambient_degC = p.inputs.ambient_degC;
      p.fast_age_s = 0.0;
      if (j == steps) {
        // The readings enter at the row.
        est->OnFrameReading(p.end_us, d.measured[0][k]);
        p.identifier = WindingReading(d, k);
      }
      est->Step(p);
    }
    if (est->counters().refused_steps > 0) {
      throw InputError(fmt::format("{}: data row {} (time_s {}): inputs the model cannot take",
                                   o.input, k + 1, t[k]));
    }
    line = fmt::format("{}", t[k]);
    const auto& e = est->estimate();
    for (std::size_t i = 0; i < e.node_degC.size(); ++i)
      fmt::format_to(std::back_inserter(line), ",{:.4f},{:.4f}", e.node_degC[i], e.node_sd_K[i]);
    daemon::AppendCsvRow(source, line);
    out << line << '\n';
  }
  return 0;
}

// ---------------------------------------------------------------------------------------------
// The paper's filter alone (Saheba et al. 2010): every --measure node, winding and magnet
// columns as extra measurements; every node of the model (massless too) in the output.

int RunPaperFilter(EstimateOptions& o) {
  const estimators::ThermalModel model = LoadThermalModel(o.model);
  o.paper.measured_nodes = MeasuredNodes(o.measure, model);
  const CsvData d = ReadCsv(o, model, o.paper.measured_nodes);
  const std::string magnet_node = o.magnet_node.empty() ? "rotor" : o.magnet_node;
  const int magnet_state = d.magnet.empty() ? -1 : model.StateIndex(magnet_node);
  if (!d.magnet.empty() && magnet_state < 0) {
    throw InputError(fmt::format("--magnet-node: '{}' is not a node with heat capacity of '{}'",
                                 magnet_node, model.Name()));
  }
  const int n = model.StateCount();
  const std::size_t m = d.measured.size();
  estimators::VirtualThermalSensor vts(model, o.paper);
  double x0 = o.initial_degC;
  if (std::isnan(x0)) {
    double sum = 0.0;
    int count = 0;
    for (const auto& col : d.measured) {
      if (std::isfinite(col[0])) sum += col[0], ++count;
    }
    x0 = count > 0 ? sum / count : d.series.ambient_degC[0];
  }
  vts.Initialise(d.x_first.size() == n ? d.x_first : Eigen::VectorXd::Constant(n, x0));
  std::vector<std::string> columns{"time_s"};
  for (const auto& node : model.Nodes()) columns.push_back(node.name + "_degC");
  for (const auto& node : model.Nodes()) columns.push_back(node.name + "_sd_K");
  columns.push_back("nis");
  CsvWriter out(o.output, columns);
  std::vector<double> row(columns.size());
  Eigen::VectorXd y(static_cast<Eigen::Index>(m));
  const Eigen::VectorXd none_measured =
      Eigen::VectorXd::Constant(static_cast<Eigen::Index>(m), std::nan(""));
  const bool linear = o.interpolation == "linear";
  estimators::NodeMeasurements extra;
  const estimators::NodeMeasurements none;
  const auto& t = d.series.time_s;
  for (std::size_t k = 0; k < t.size(); ++k) {
    estimators::KalmanUpdateReport rep;
    if (k > 0) {
      for (std::size_t j = 0; j < m; ++j) y(static_cast<Eigen::Index>(j)) = d.measured[j][k];
      extra.Clear();
      if (!d.winding.empty())
        extra.Add(estimators::kWindingWeightsRow, d.winding[k], o.paper.winding_measurement_sd_K);
      if (!d.magnet.empty()) extra.Add(magnet_state, d.magnet[k], o.magnet_sd_K);
      const double dt_s = t[k] - t[k - 1];
      const int steps = StepsOfRow(o, dt_s);
      for (int j = 0; j + 1 < steps; ++j)
        vts.Step(d.series.Between(k, static_cast<double>(j) / steps, linear), dt_s / steps,
                 none_measured, none);
      rep = vts.Step(d.series.Between(k, static_cast<double>(steps - 1) / steps, linear),
                     dt_s / steps, y, extra);
      if (rep.refused) {
        throw InputError(fmt::format("{}: data row {} (time_s {}): inputs the model cannot take",
                                     o.input, k + 1, t[k]));
      }
    }
    const estimators::ThermalInputs in = d.series.Inputs(k);
    const Eigen::VectorXd all = model.AllTemperatures_degC(in, vts.Estimate_degC());
    const Eigen::MatrixXd jac = model.AllTemperatureJacobian(in);
    const Eigen::VectorXd var = (jac * vts.Covariance_K2() * jac.transpose()).diagonal();
    std::size_t c = 0;
    row[c++] = t[k];
    for (Eigen::Index i = 0; i < all.size(); ++i) row[c++] = all(i);
    for (Eigen::Index i = 0; i < all.size(); ++i) row[c++] = std::sqrt(std::max(var(i), 0.0));
    row[c++] = k > 0 && rep.measurements > 0 ? rep.nis : std::nan("");
    out.Row(row);
  }
  out.Close();
  return 0;
}

int RunEstimate(EstimateOptions& o) {
  if (o.input.empty() == o.recording.log.empty())
    throw InputError("give --input CSV or --log RECORDING");
  if (o.config.empty() != o.pump.empty()) throw InputError("--config and --pump go together");
  if (o.filter != "auto" && o.filter != "disturbance" && o.filter != "standard") {
    throw InputError(
        fmt::format("--filter: '{}' is none of auto, disturbance, standard", o.filter));
  }
  if (o.interpolation != "hold" && o.interpolation != "linear") {
    throw InputError(fmt::format("--inputs: '{}' is neither 'hold' nor 'linear'", o.interpolation));
  }
  if (!(o.max_step_s >= 0.0) || !std::isfinite(o.max_step_s))
    throw InputError("--max-step-s: must be a finite number >= 0");
  if (!(o.sensor_lag_s >= 0.0) || !std::isfinite(o.sensor_lag_s))
    throw InputError("--sensor-lag-s: must be a finite number >= 0");
  if (o.paper_filter) {
    if (o.input.empty()) throw InputError("--paper-filter reads --input CSV");
    return RunPaperFilter(o);
  }
  for (const CLI::Option* option : o.paper_only) {
    if (option->count() > 0) {
      throw InputError(
          fmt::format("{} is for --paper-filter (the pump estimator takes the daemon's settings)",
                      option->get_name()));
    }
  }
  return o.recording.log.empty() ? RunCsvEstimator(o) : RunRecording(o);
}

void AddPaperOptions(CLI::App& app, EstimateOptions& o) {
  app.add_flag("--paper-filter", o.paper_filter,
               "The virtual thermal sensor of Saheba et al. 2010 alone over --input (every "
               "--measure node, --winding-column and --magnet-column as measurements; every "
               "node of the model in the output) instead of the daemon's pump estimator");
  o.paper_only.push_back(
      app.add_option("--magnet-column", o.magnet_column,
                     "with --paper-filter: column with a magnet temperature, degC, fused as a "
                     "reading of --magnet-node"));
  o.paper_only.push_back(
      app.add_option("--magnet-sd-K", o.magnet_sd_K, "with --paper-filter: its sd")
          ->capture_default_str());
  o.paper_only.push_back(
      app.add_option("--measurement-sd-K", o.paper.measurement_sd_K,
                     "with --paper-filter: node sensor noise (Saheba 2010 eq. 38)")
          ->capture_default_str());
  o.paper_only.push_back(
      app.add_option("--process-sd-K", o.paper.process_sd_K,
                     "with --paper-filter: process noise per state per second (eq. 39)")
          ->capture_default_str());
  o.paper_only.push_back(app.add_option("--winding-sd-K", o.paper.winding_measurement_sd_K,
                                        "with --paper-filter: noise of the winding column")
                             ->capture_default_str());
  o.paper_only.push_back(app.add_option("--initial-sd-K", o.paper.initial_sd_K,
                                        "with --paper-filter: initial uncertainty common to all "
                                        "nodes")
                             ->capture_default_str());
  o.paper_only.push_back(app.add_option("--initial-spread-sd-K", o.paper.initial_spread_sd_K,
                                        "with --paper-filter: initial uncertainty of each node "
                                        "on its own")
                             ->capture_default_str());
  o.paper_only.push_back(app.add_option(
      "--initial-C", o.initial_degC, "with --paper-filter: initial estimate of every node, degC"));
  o.paper_only.push_back(
      app.add_option(
             "--initial", o.initial,
             "with --paper-filter: 'measured' (every node at the mean of the first measured "
             "values) or 'first-row' (each node at its <node>_degC of the first row)")
          ->capture_default_str());
}

const SubcommandRegistrar kEstimateRegistrar{
    "estimate",
    "The daemon's pump estimator over a recording or a CSV (or the paper's filter alone)",
    [](CLI::App& app) -> std::function<int()> {
      auto o = std::make_shared<EstimateOptions>();
      app.add_option("--config", o->config,
                     "The daemon's configuration file: the settings of --pump from it");
      app.add_option("--pump", o->pump, "with --config: the [[pump]] to run");
      app.add_option("--model,-m", o->model, "Without --config: shipped model name or path")
          ->capture_default_str();
      app.add_option(
          "--input,-i", o->input,
          "CSV with time_s, speed_rpm, id_A, iq_A, ambient_degC (coolant_degC if the model "
          "has a coolant) and <node>_degC of the measured node (empty or nan: not "
          "measured); or --log");
      AddRecordingOptions(app, o->recording);
      app.add_option("--motor", o->recording.motor, "Without --config: motor preset or file")
          ->capture_default_str();
      app.add_option("--output,-o", o->output,
                     "CSV to write ('-': standard output): the daemon's CSV (docs/daemon.md, "
                     "\"Outputs\"), a row per thermal step")
          ->capture_default_str();
      app.add_option("--measure", o->measure,
                     "Without --config: the node the frame sensor measures (--paper-filter: "
                     "nodes, comma-separated)")
          ->capture_default_str();
      app.add_option("--magnet-node", o->magnet_node,
                     "Without --config: the node the magnet temperature from the flux is fused "
                     "into (the daemon's magnet_node; --paper-filter: the node --magnet-column "
                     "reads, default rotor)");
      app.add_option("--sensor-lag-s", o->sensor_lag_s,
                     "Without --config: the frame sensor's first-order lag, s "
                     "(frame_sensor_lag_s)")
          ->capture_default_str();
      app.add_option("--filter", o->filter,
                     "Without --config: auto (what the daemon ships for the model), disturbance "
                     "or standard (the daemon's disturbance_states)")
          ->capture_default_str();
      app.add_option("--thermal-period-s", o->thermal_period_s,
                     "Without --config: the thermal period, s")
          ->capture_default_str();
      app.add_option("--csv-time-origin", o->csv_time_origin_s,
                     "With --log: subtracted from the frames' Unix time in time_s (as "
                     "pumpthermd's --csv-time-origin; default: the recording's first whole "
                     "second; 0: Unix time)");
      app.add_option("--winding-column", o->winding_column,
                     "With --input: column with the winding temperature from resistance "
                     "identification, degC (the identifier's, tracking)");
      app.add_option("--columns", o->columns,
                     "With --input: column names of a known data set: 'paderborn'");
      app.add_option("--max-step-s", o->max_step_s,
                     "With --input: longest step, s; rows further apart are split and the "
                     "readings enter at the rows (0 = one step per row)")
          ->capture_default_str();
      app.add_option("--inputs", o->interpolation,
                     "With --input: inputs between rows, 'hold' or 'linear'")
          ->capture_default_str();
      AddPaperOptions(app, *o);
      app.footer(
          "Examples:\n"
          "  pumptherm estimate --config /etc/pumptherm/pumpthermd.toml --pump pump3 --log "
          "bus.log -o pump3.csv\n"
          "  pumptherm estimate --model tmp-generic --log demo.log --node-id 3 --magnet-node "
          "rotor --sensor-lag-s 30 -o e.csv\n"
          "  pumptherm estimate --model saheba2010-improved --input measured.csv -o est.csv\n"
          "  pumptherm estimate --paper-filter --model tests/data/models/wallscheid2017-4node.toml "
          "--columns paderborn --measure stator_yoke --input profile46.csv");
      return [o] { return RunEstimate(*o); };
    }};

}  // namespace
}  // namespace pumptherm::tools
