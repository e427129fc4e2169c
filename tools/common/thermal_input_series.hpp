#pragma once
/// A thermal model's inputs over time, one sample per row of a CSV table: what
/// `pumptherm simulate`, `pumptherm estimate`, the discrepancy workflow and the figures read.

#include <functional>
#include <string>
#include <vector>

#include "estimators/thermal_model.hpp"
#include "tools/common/csv.hpp"

namespace pumptherm::tools {

/// Every vector has one value per row.
struct ThermalInputSeries {
  std::vector<double> time_s, speed_rpm, id_A, iq_A, ambient_degC, coolant_degC;

  std::size_t size() const { return time_s.size(); }
  /// The inputs of row `k`.
  estimators::ThermalInputs Inputs(std::size_t k) const;
  /// The inputs a fraction `w` (0 to 1) of the way from row k-1 to row k (k >= 1): those of row
  /// k-1 held, or interpolated linearly (estimators::InterpolateInputs) when `linear`.
  estimators::ThermalInputs Between(std::size_t k, double w, bool linear) const;
};

/// How ReadThermalInputs finds its columns.
struct ThermalInputColumns {
  /// The table's name for each of the project's names (time_s, speed_rpm, id_A, iq_A, ambient_degC,
  /// coolant_degC); empty: the project's names.
  std::function<std::string(const std::string&)> name;
  /// Read coolant_degC; otherwise the coolant equals the ambient.
  bool coolant = false;
  /// Without id_A and iq_A, take phase_current_rms_A as id = 0, iq = sqrt(2) I_rms
  /// (amplitude-invariant dq, the same copper loss).
  bool rms_current = false;
};

/// Reads the inputs from `csv`. Throws CsvError (file, row, column) for a missing column or a
/// cell that is not a number.
ThermalInputSeries ReadThermalInputs(const CsvTable& csv, const ThermalInputColumns& columns = {});

}  // namespace pumptherm::tools
