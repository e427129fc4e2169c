#include "tools/discrepancy/data.hpp"

#include <fmt/core.h>

#include <cmath>

#include "tools/common/csv.hpp"

namespace pumptherm::tools::discrepancy {

estimators::ThermalInputs Data::Inputs(std::size_t k) const {
  estimators::ThermalInputs in;
  in.speed_rpm = speed_rpm[k];
  in.id_A = id_A[k];
  in.iq_A = iq_A[k];
  in.ambient_degC = ambient_degC[k];
  in.coolant_degC = coolant_degC[k];
  return in;
}

Data ReadData(const std::string& path, const estimators::ThermalModel& model) {
  const CsvTable csv = CsvTable::Read(path);
  Data d;
  d.source = path;
  d.time_s = csv.Time();
  if (d.time_s.size() < 3)
    throw CsvError(fmt::format("{}: {} data rows, need at least 3", path, d.time_s.size()));
  d.speed_rpm = csv.Column("speed_rpm");
  if (csv.Has("id_A") || csv.Has("iq_A") || !csv.Has("phase_current_rms_A")) {
    d.id_A = csv.Column("id_A");
    d.iq_A = csv.Column("iq_A");
  } else {
    const std::vector<double> rms = csv.Column("phase_current_rms_A");
    d.id_A.assign(rms.size(), 0.0);
    for (double r : rms) d.iq_A.push_back(std::sqrt(2.0) * r);
  }
  d.ambient_degC = csv.Column("ambient_C");
  d.coolant_degC = model.UsesCoolant() ? csv.Column("coolant_C") : d.ambient_degC;
  for (const auto& node : model.Nodes())
    if (csv.Has(node.name + "_C")) d.measured.push_back({node.name, csv.Column(node.name + "_C")});
  if (d.measured.empty()) {
    std::string names;
    for (const auto& node : model.Nodes()) names += (names.empty() ? "" : ", ") + node.name + "_C";
    throw CsvError(fmt::format("{}: no measured temperature column (the model's nodes: {})", path,
                               names));
  }
  return d;
}

void WriteData(const std::string& path, const Data& data, bool with_coolant) {
  std::vector<std::string> cols{"time_s", "speed_rpm", "id_A", "iq_A", "ambient_C"};
  if (with_coolant) cols.push_back("coolant_C");
  for (const auto& m : data.measured) cols.push_back(m.node + "_C");
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
