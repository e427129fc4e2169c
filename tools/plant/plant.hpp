#pragma once
/// The pump plant simulator behind `pumptherm plant` (docs/plant-simulator.md).
///
/// Per pump: a load profile sets speed and dq current set points; the drive's electrical model
/// (Han, Xiong, Mao, Vacuum 169 (2019) 108935, eq. 4, the SPMSM in dq under current control)
/// turns them into the voltages and currents the drive reports, with the imperfections of
/// ../shared/reference/realistic-signals.md; the true currents and speed drive the losses of a
/// thermal model (the truth, integrated exactly: Saheba et al. 2010 eqs. 20-21, with process
/// noise), whose winding temperature (ThermalModel::WindingWeights) sets the drive's Rs through
/// the copper law (Han 2019 eq. 2), so electrical and thermal data agree. Sensors (frame RTD,
/// ambient) add lag, offset, noise and quantisation. Frames are encoded through the DBC and the
/// signal mapping, time-stamped with jitter, merged in time order across pumps and written as a
/// candump log. Faults: dropped frames, stale sensor, stuck sensor, bus-off bursts, cooling
/// failure (an edge's resistance scaled). The true motor may differ from the nameplate (R0 and
/// flux scaled); the rotor may carry a mechanical speed ripple that the speed estimate does not
/// show. Same scenario and seed => the same bytes.

#include <cstdint>
#include <functional>
#include <string>
#include <string_view>
#include <utility>
#include <vector>

#include "tools/plant/scenario.hpp"

namespace pumptherm::plant {

/// Text of a referenced file and a name for it in messages.
struct LoadedText {
  std::string text;
  std::string source;
};

/// Where the plant gets the files a scenario names. Each function throws (any exception, passed
/// on) when the reference cannot be resolved.
struct PlantResources {
  std::function<LoadedText(const std::string& model_ref)> model;
  /// Motor file text for a path; preset names are resolved without calling it.
  std::function<LoadedText(const std::string& motor_ref)> motor_file;
  /// Contents of a file a model names (loss maps, `[[table]]`), by path (relative paths are
  /// already joined to the model file's directory). Unset: a model with tables is an error.
  std::function<std::string(const std::string& path)> read_file;
  LoadedText dbc;      ///< the frame layout (protocol/pumptherm.dbc)
  LoadedText mapping;  ///< the signal mapping (protocol/mapping_pumptherm.toml)
};

/// What one pump did, for people and tests (also written to summary.json).
struct PumpSummary {
  std::string name;
  std::string interface;
  std::uint32_t node_id = 0;
  double max_level_node_degC = 0.0;  ///< highest truth of the levels' node
  double max_level_time_s = 0.0;
  double warning_crossed_s = -1.0;  ///< first time the truth exceeds warning_C (-1 = never)
  double trip_crossed_s = -1.0;     ///< first time the truth exceeds trip_C (-1 = never)
  /// Every interval in which the truth was above warning_C: [start, end) at thermal-step
  /// resolution; end -1 = still above at the end of the run.
  std::vector<std::pair<double, double>> above_warning_s;
  std::uint64_t frames_written = 0;
  std::uint64_t frames_suppressed = 0;  ///< by faults (dropped, stale, bus-off)
};

struct PlantResult {
  std::vector<PumpSummary> pumps;
  std::uint64_t frames_written = 0;
  std::string log_path;  ///< empty for a thermal-only scenario
};

/// Runs `scenario` and writes into `out_dir` (created if missing):
///   <scenario>.log             candump log of every pump (unless can_log = false)
///   <pump>.truth.csv           truth per pump
///   <pump>.measured.csv        measured inputs and sensors per pump
///   summary.json               PumpSummary per pump and the levels used
/// `progress` (may be empty) is called with the fraction done, about every 1 %.
/// Throws ScenarioError for references that do not resolve or do not fit (unknown node, edge
/// or motor), std::system_error when an output cannot be written.
PlantResult RunPlant(const Scenario& scenario, const PlantResources& resources,
                     const std::string& out_dir, const std::function<void(double)>& progress = {});

/// Model text with edge `edge`'s resistance multiplied by `factor` (the cooling-failure fault).
/// `edge` matches an edge's `name`, or "a-b" / "b-a" of its `between`. A number is multiplied;
/// an expression becomes "(expr) * factor". Throws ScenarioError when no edge matches or the
/// text does not parse as TOML.
std::string ScaleEdgeResistance(std::string_view model_text, const std::string& source,
                                const std::string& edge, double factor);

/// Model text with every copper loss (a `[[loss]]` with `temperature_coefficient_per_K`)
/// multiplied by `factor`: a true motor whose R0 is `factor` times the nameplate's. A number is
/// multiplied; an expression becomes "(expr) * factor". Throws ScenarioError when the model has
/// no copper loss or the text does not parse as TOML.
std::string ScaleCopperLosses(std::string_view model_text, const std::string& source,
                              double factor);

}  // namespace pumptherm::plant
