#include "tools/common/thermal_input_series.hpp"

#include <cmath>

namespace pumptherm::tools {

estimators::ThermalInputs ThermalInputSeries::Inputs(std::size_t k) const {
  estimators::ThermalInputs in;
  in.speed_rpm = speed_rpm[k];
  in.id_A = id_A[k];
  in.iq_A = iq_A[k];
  in.ambient_degC = ambient_degC[k];
  in.coolant_degC = coolant_degC[k];
  return in;
}

estimators::ThermalInputs ThermalInputSeries::Between(std::size_t k, double w, bool linear) const {
  const estimators::ThermalInputs a = Inputs(k - 1);
  return linear ? estimators::InterpolateInputs(a, Inputs(k), w) : a;
}

ThermalInputSeries ReadThermalInputs(const CsvTable& csv, const ThermalInputColumns& columns) {
  auto name = [&](const std::string& standard) {
    return columns.name ? columns.name(standard) : standard;
  };
  ThermalInputSeries s;
  s.time_s = csv.Time(name("time_s"));
  s.speed_rpm = csv.Column(name("speed_rpm"));
  if (columns.rms_current && !csv.Has(name("id_A")) && !csv.Has(name("iq_A")) &&
      csv.Has(name("phase_current_rms_A"))) {
    const std::vector<double> rms = csv.Column(name("phase_current_rms_A"));
    s.id_A.assign(rms.size(), 0.0);
    for (double r : rms) s.iq_A.push_back(std::sqrt(2.0) * r);
  } else {
    s.id_A = csv.Column(name("id_A"));
    s.iq_A = csv.Column(name("iq_A"));
  }
  s.ambient_degC = csv.Column(name("ambient_degC"));
  s.coolant_degC = columns.coolant ? csv.Column(name("coolant_degC")) : s.ambient_degC;
  return s;
}

}  // namespace pumptherm::tools
