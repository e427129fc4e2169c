// The bundled `demo` scenario keeps its promise (the README demo and the daemon's demo test rely
// on it): pump 3's true winding temperature crosses the warning level and then the trip level
// within the 20 minutes, after its cooling fails; pumps 1 and 2 stay well below the warning level.
#include <gtest/gtest.h>

#include <filesystem>
#include <fstream>
#include <sstream>

#include "tests/common/test_files.hpp"
#include "tools/common/csv.hpp"
#include "tools/plant/plant.hpp"

namespace pumptherm::plant {
namespace {

using pumptherm::test_files::ReadFile;

namespace fs = std::filesystem;

TEST(PlantDemo, Pump3WarnsThenTripsPumps1And2StayBelowWarning) {
  const char* env = std::getenv("PUMPTHERM_SOURCE_DIR");
  const fs::path src = env != nullptr ? env : ".";
  const fs::path path = src / "tools" / "plant" / "scenarios" / "demo.toml";
  const Scenario sc = ParseScenario(ReadFile(path), path.string());
  ASSERT_EQ(sc.pumps.size(), 3u);
  EXPECT_DOUBLE_EQ(sc.duration_s, 1200.0);
  EXPECT_EQ(sc.levels.node, "winding_resistance");
  EXPECT_DOUBLE_EQ(sc.levels.warning_degC, 100.0);
  EXPECT_DOUBLE_EQ(sc.levels.trip_degC, 120.0);

  PlantResources res;
  res.model = [&](const std::string& ref) {
    const fs::path p = src / "estimators" / "models" / (ref + ".toml");
    return LoadedText{ReadFile(p), p.string()};
  };
  res.motor_file = [](const std::string& ref) -> LoadedText {
    throw std::runtime_error("no motor file " + ref);
  };
  res.dbc = {ReadFile(src / "protocol" / "pumptherm.dbc"), "pumptherm.dbc"};
  res.mapping = {ReadFile(src / "protocol" / "mapping_pumptherm.toml"), "mapping_pumptherm.toml"};
  const fs::path out = fs::path(testing::TempDir()) / "pumptherm_plant_demo";
  fs::remove_all(out);
  const PlantResult r = RunPlant(sc, res, out.string());
  ASSERT_EQ(r.pumps.size(), 3u);

  constexpr double kMarginK = 15.0;  // pumps 1 and 2 stay at least this far below warning
  for (int i = 0; i < 2; ++i) {
    const PumpSummary& p = r.pumps[static_cast<std::size_t>(i)];
    EXPECT_LT(p.max_level_node_degC, sc.levels.warning_degC - kMarginK) << p.name;
    EXPECT_LT(p.warning_crossed_s, 0.0) << p.name;
    // ... and they do heat up: a winding well above ambient in operation (40-90 degC band).
    EXPECT_GT(p.max_level_node_degC, 40.0) << p.name;
  }
  const PumpSummary& p3 = r.pumps[2];
  const double failure_s = sc.pumps[2].faults.at(0).start_s;
  EXPECT_GT(p3.warning_crossed_s, failure_s) << "pump3 warns only after its cooling fails";
  EXPECT_GT(p3.trip_crossed_s, p3.warning_crossed_s);
  EXPECT_LT(p3.trip_crossed_s, sc.duration_s - 60.0) << "trip with a minute to spare";
  // The truth CSV says the same (it is what the daemon's demo test compares against).
  const tools::CsvTable truth = tools::CsvTable::Read((out / "pump3.truth.csv").string());
  const auto t = truth.Time();
  const auto w = truth.Column("winding_resistance_degC");
  double first_warning = -1.0;
  for (std::size_t k = 0; k < w.size(); ++k) {
    if (w[k] > 100.0) {
      first_warning = t[k];
      break;
    }
  }
  EXPECT_NEAR(first_warning, p3.warning_crossed_s, 1.0);
  // Above-warning intervals (the soak's alarm check reads them): none on pumps 1-2; pump 3's
  // first starts at its warning crossing, and the last is still open at the end (it trips).
  EXPECT_TRUE(r.pumps[0].above_warning_s.empty());
  EXPECT_TRUE(r.pumps[1].above_warning_s.empty());
  ASSERT_FALSE(p3.above_warning_s.empty());
  EXPECT_DOUBLE_EQ(p3.above_warning_s.front().first, p3.warning_crossed_s);
  EXPECT_LT(p3.above_warning_s.back().second, 0.0) << "still above warning at the end";
  for (std::size_t k = 0; k + 1 < p3.above_warning_s.size(); ++k) {
    EXPECT_LT(p3.above_warning_s[k].first, p3.above_warning_s[k].second);
    EXPECT_LE(p3.above_warning_s[k].second, p3.above_warning_s[k + 1].first);
  }
  std::printf(
      "demo: pump1 max %.1f degC, pump2 max %.1f degC, pump3 warning at %.0f s, trip at %.0f s\n",
      r.pumps[0].max_level_node_degC, r.pumps[1].max_level_node_degC, p3.warning_crossed_s,
      p3.trip_crossed_s);
}

}  // namespace
}  // namespace pumptherm::plant
