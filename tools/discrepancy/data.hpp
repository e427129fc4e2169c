#pragma once
/// The discrepancy workflow's data: inputs and measured node temperatures over time,
/// read from and written to its CSV format (time_s, speed_rpm, id_A + iq_A or
/// phase_current_rms_A, ambient_degC, coolant_degC where the model has a coolant, <node>_degC per
/// measured node; other columns ignored). Reading takes a temperature under `_C` too (files written
/// before), and a node's measurement as `<node>_sensor_degC` (docs/daemon.md, "Names").

#include <string>
#include <vector>

#include "estimators/thermal_model.hpp"
#include "tools/common/thermal_input_series.hpp"

namespace pumptherm::tools::discrepancy {

/// One measured node's series.
struct MeasuredNode {
  std::string node;
  std::vector<double> value_degC;
};

/// A data set: the inputs and the measured series, every vector with one value per row.
struct Data : ThermalInputSeries {
  std::string source;                  ///< file name for messages
  std::vector<MeasuredNode> measured;  ///< in the model's node order
};

/// Reads a CSV for `model`. Throws CsvError (file, row, column) for bad cells or a missing
/// input column, and CsvError when no column `<node>_sensor_degC` or `<node>_degC` matches a node
/// of the model or there are fewer than 3 rows. phase_current_rms_A (when id_A/iq_A are absent)
/// becomes id = 0, iq = sqrt(2) I_rms (amplitude-invariant dq, same copper loss).
Data ReadData(const std::string& path, const estimators::ThermalModel& model);

/// Writes `data` as the workflow's CSV (id_A/iq_A; coolant_degC only when `with_coolant`).
void WriteData(const std::string& path, const Data& data, bool with_coolant);

}  // namespace pumptherm::tools::discrepancy
