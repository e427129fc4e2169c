// libFuzzer target: the tools' CSV reader (tools/common/csv.hpp) on arbitrary text. CsvError is
// the expected answer to bad input, at parse time or when a column is read. Every value a
// column read returns must be finite (Column, Time) or finite-or-NaN (ColumnAllowingNaN), and
// Time() strictly increasing. Anything else is a finding.
#include <cmath>
#include <cstdint>
#include <cstdlib>
#include <string_view>
#include <vector>

#include "tools/common/csv.hpp"

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  using namespace pumptherm::tools;
  const std::string_view text(reinterpret_cast<const char*>(data), size);
  try {
    const CsvTable t = CsvTable::Parse(text, "fuzz.csv");
    for (const auto& c : t.columns()) {
      try {
        for (double x : t.Column(c)) {
          if (!std::isfinite(x)) std::abort();
        }
      } catch (const CsvError&) {
      }
      try {
        for (double x : t.ColumnAllowingNaN(c)) {
          if (std::isinf(x)) std::abort();
        }
      } catch (const CsvError&) {
      }
      try {
        const std::vector<double> time = t.Time(c);
        for (std::size_t i = 1; i < time.size(); ++i) {
          if (!(time[i] > time[i - 1])) std::abort();
        }
      } catch (const CsvError&) {
      }
    }
  } catch (const CsvError&) {
  }
  return 0;
}
