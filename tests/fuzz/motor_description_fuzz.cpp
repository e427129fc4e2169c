// libFuzzer target: the motor description reader (estimators/motor.hpp) on arbitrary text.
// A MotorDescriptionError is the expected answer to bad input; an accepted description must
// hold the documented ranges (pole_pairs >= 1; positive, finite speed, flux, inductance, R0 and
// alpha; a non-empty plausibility band; a uq resolution of 0 (absent) or within (0, 10] V).
// Anything else is a finding.
#include <cmath>
#include <cstdint>
#include <cstdlib>
#include <string_view>

#include "estimators/motor.hpp"

namespace {
bool PositiveFinite(double x) { return std::isfinite(x) && x > 0.0; }
}  // namespace

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  using namespace pumptherm::estimators;
  const std::string_view text(reinterpret_cast<const char*>(data), size);
  MotorDescription m;
  try {
    m = ParseMotorDescription(text, "fuzz.toml");
  } catch (const MotorDescriptionError&) {
    return 0;
  }
  if (m.pole_pairs < 1) std::abort();
  if (!PositiveFinite(m.rated_speed_rpm) || !PositiveFinite(m.flux_Wb) ||
      !PositiveFinite(m.inductance_H))
    std::abort();
  if (!std::isfinite(m.plausible_min_degC) || !std::isfinite(m.plausible_max_degC) ||
      !(m.plausible_min_degC < m.plausible_max_degC)) {
    std::abort();
  }
  if (!(m.uq_resolution_V == 0.0 || (m.uq_resolution_V > 0.0 && m.uq_resolution_V <= 10.0)))
    std::abort();
  const double lo = PlausibleMinResistance_ohm(m), hi = PlausibleMaxResistance_ohm(m);
  if (!std::isfinite(lo) || !std::isfinite(hi) || !(lo < hi)) std::abort();
  return 0;
}
