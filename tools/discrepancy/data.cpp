#include "tools/discrepancy/data.hpp"

#include <fmt/core.h>

#include <cmath>

#include "tools/common/csv.hpp"

namespace pumptherm::tools::discrepancy {

Data ReadData(const std::string& path, const estimators::ThermalModel& model) {
  const CsvTable csv = CsvTable::Read(path);
  if (const std::size_t rows = csv.Time().size(); rows < 3)
    throw CsvError(fmt::format("{}: {} data rows, need at least 3", path, rows));
  Data d;
  ThermalInputColumns columns;
  columns.coolant = model.UsesCoolant();
  columns.rms_current = true;
  static_cast<ThermalInputSeries&>(d) = ReadThermalInputs(csv, columns);
  d.source = path;
  // A node's measurement: `<node>_sensor_degC` (docs/daemon.md, "Names"), or `<node>_degC` /
  // `<node>_C` as measured CSV files write it (either suffix).
  for (const auto& node : model.Nodes()) {
    for (const std::string& column : {node.name + "_sensor_degC", node.name + "_degC"}) {
      if (!csv.Has(column)) continue;
      d.measured.push_back({node.name, csv.Column(column)});
      break;
    }
  }
  if (d.measured.empty()) {
    std::string names;
    for (const auto& node : model.Nodes())
      names += (names.empty() ? "" : ", ") + node.name + "_sensor_degC";
    throw CsvError(
        fmt::format("{}: no measured temperature column (the model's nodes: {})", path, names));
  }
  return d;
}

void WriteData(const std::string& path, const Data& data, bool with_coolant) {
  std::vector<std::string> cols{"time_s", "speed_rpm", "id_A", "iq_A", "ambient_degC"};
  if (with_coolant) cols.push_back("coolant_degC");
  for (const auto& m : data.measured) cols.push_back(m.node + "_degC");
  CsvWriter w(path, cols);
  std::vector<double> row;
  for (std::size_t k = 0; k < data.size(); ++k) {
    row = {data.time_s[k], data.speed_rpm[k], data.id_A[k], data.iq_A[k], data.ambient_degC[k]};
    if (with_coolant) row.push_back(data.coolant_degC[k]);
    for (const auto& m : data.measured) row.push_back(m.value_degC[k]);
    w.Row(row);
  }
  w.Close();
}

}  // namespace pumptherm::tools::discrepancy
