// libFuzzer target: the thermal model reader (estimators/thermal_model.hpp) on arbitrary text.
// A ThermalModelError is the expected answer to bad input. For a model it accepts, linearising
// at the default inputs either works (finite matrices of the stated shape) or throws the
// documented std::domain_error. Anything else (another exception, a crash, a sanitizer
// report, a NaN in an accepted model's matrices) is a finding.
#include <cstdint>
#include <cstdlib>
#include <stdexcept>
#include <string_view>

#include "estimators/thermal_model.hpp"

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  using namespace pumptherm::estimators;
  const std::string_view text(reinterpret_cast<const char*>(data), size);
  try {
    const ThermalModel model = ThermalModel::Parse(text, "fuzz.toml");
    const int n = model.StateCount();
    if (n < 0 || static_cast<std::size_t>(n) > model.Nodes().size()) std::abort();
    if (n > 64) return 0;  // large networks cost time, not coverage
    ThermalLinearModel lin;
    try {
      model.Linearise(ThermalInputs{}, lin);
    } catch (const std::domain_error&) {
      return 0;
    }
    if (lin.a_per_s.rows() != n || lin.a_per_s.cols() != n || lin.f_K_per_s.size() != n)
      std::abort();
  } catch (const ThermalModelError&) {
  }
  return 0;
}
