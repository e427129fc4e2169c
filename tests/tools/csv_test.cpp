#include "tools/common/csv.hpp"

#include <gtest/gtest.h>

#include <array>
#include <cmath>
#include <string_view>

namespace pumptherm::tools {
namespace {

std::string ErrorOf(const std::function<void()>& f) {
  try {
    f();
  } catch (const CsvError& e) {
    return e.what();
  }
  return "";
}

TEST(Csv, ReadsColumnsByName) {
  const auto t = CsvTable::Parse("time_s, iq_A ,x\n0,1.5,a\n1,-2e-3,b\n\n", "t.csv");
  EXPECT_EQ(t.rows(), 2U);
  EXPECT_EQ(t.Column("iq_A"), (std::vector<double>{1.5, -2e-3}));
  EXPECT_EQ(t.Time(), (std::vector<double>{0.0, 1.0}));
  EXPECT_TRUE(t.Has("x"));
  EXPECT_FALSE(t.Has("y"));
}

TEST(Csv, OldColumnNamesAreReadUnderTheCurrentOneWithAWarning) {
  // pumptherm plant's truth before one name per quantity, and identify's output.
  const auto plant = CsvTable::Parse("time_s,winding_C,winding_res_C\n0,40,41.5\n", "truth.csv");
  EXPECT_EQ(plant.Column("winding_resistance_degC"), std::vector<double>{41.5});
  EXPECT_FALSE(plant.Has("winding_res_C"));
  ASSERT_EQ(plant.deprecations().size(), 1U);
  EXPECT_EQ(plant.deprecations()[0],
            "truth.csv:1: column 'winding_res_C' is deprecated: read as 'winding_resistance_degC'");
  const auto identify = CsvTable::Parse("time_s,winding_degC\n0,30\n", "rs.csv");
  EXPECT_EQ(identify.Column("winding_resistance_degC"), std::vector<double>{30.0});
  // The daemon's CSV before one name per quantity: the frame sensor's reading.
  const auto daemon = CsvTable::Parse("time_s,frame_C,frame_measured_C\n0,40,39.5\n", "p.csv");
  EXPECT_EQ(daemon.Column("frame_sensor_degC"), std::vector<double>{39.5});
  EXPECT_EQ(daemon.Column("frame_degC"), std::vector<double>{40.0});
  // A file with the current name is read as it is, and one with both keeps both.
  const auto both = CsvTable::Parse("time_s,winding_res_C,winding_resistance_C\n0,1,2\n", "b.csv");
  EXPECT_TRUE(both.deprecations().empty());
  EXPECT_EQ(both.Column("winding_resistance_C"), std::vector<double>{2.0});
  EXPECT_TRUE(
      CsvTable::Parse("time_s,winding_resistance_C\n0,1\n", "n.csv").deprecations().empty());
}

TEST(Csv, ATemperatureIsReadUnderEitherUnitSuffix) {
  // docs/daemon.md, "Names": _degC, the files written before _C; the same quantity.
  const auto old_file = CsvTable::Parse("time_s,frame_C\n0,40.5\n", "old.csv");
  EXPECT_TRUE(old_file.Has("frame_degC"));
  EXPECT_EQ(old_file.Column("frame_degC"), std::vector<double>{40.5});
  const auto new_file = CsvTable::Parse("time_s,frame_degC,speed_rpm\n0,41.5,7\n", "new.csv");
  EXPECT_EQ(new_file.Column("frame_C"), std::vector<double>{41.5});
  EXPECT_FALSE(new_file.Has("speed_C")) << "only temperatures have two spellings";
  EXPECT_TRUE(old_file.deprecations().empty()) << "a suffix is no deprecated name";
}

TEST(Csv, CodesAreReadAsWordsOrNumbers) {
  constexpr std::array<std::string_view, 3> kLevels{"normal", "warning", "trip"};
  const auto t = CsvTable::Parse("time_s,level\n0,normal\n1,2\n2,trip\n3,nan\n4,\n", "c.csv");
  const auto v = t.Codes("level", kLevels);
  ASSERT_EQ(v.size(), 5U);
  EXPECT_EQ(v[0], 0.0);
  EXPECT_EQ(v[1], 2.0);
  EXPECT_EQ(v[2], 2.0);
  EXPECT_TRUE(std::isnan(v[3]) && std::isnan(v[4]));
  const auto bad = CsvTable::Parse("time_s,level\n0,tripped\n", "bad.csv");
  EXPECT_EQ(ErrorOf([&] { bad.Codes("level", kLevels); }),
            "bad.csv: row 2, column 'level': 'tripped' is neither a number nor one of normal, "
            "warning, trip");
  EXPECT_EQ(t.Text("level")[0], "normal");
}

TEST(Csv, ErrorsNameFileRowAndColumn) {
  const auto t = CsvTable::Parse("time_s,iq_A\n0,1\n1,abc\n2,nan\n3,inf\n", "t.csv");
  EXPECT_EQ(ErrorOf([&] { t.Column("iq_A"); }),
            "t.csv: row 3, column 'iq_A': 'abc' is not a number");
  EXPECT_EQ(ErrorOf([&] { t.Column("uq_V"); }),
            "t.csv: missing column 'uq_V' (the header has: time_s, iq_A)");
  const auto u = CsvTable::Parse("time_s,iq_A\n0,1\n1,nan\n", "u.csv");
  EXPECT_EQ(ErrorOf([&] { u.Column("iq_A"); }),
            "u.csv: row 3, column 'iq_A': 'nan' is not a finite number");
  EXPECT_TRUE(std::isnan(u.ColumnAllowingNaN("iq_A")[1]));
  const auto v = CsvTable::Parse("time_s,iq_A\n0,1\n2,1\n1,1\n", "v.csv");
  EXPECT_EQ(ErrorOf([&] { v.Time(); }),
            "v.csv: row 4, column 'time_s': time 1 does not advance past 2");
  EXPECT_EQ(ErrorOf([] { CsvTable::Parse("a,b\n1\n", "w.csv"); }),
            "w.csv: row 2: 1 cells, but the header has 2 columns");
  EXPECT_EQ(ErrorOf([] { CsvTable::Parse("a,a\n", "d.csv"); }),
            "d.csv:1: column 'a' appears twice in the header");
  EXPECT_EQ(ErrorOf([] { CsvTable::Parse("\n\n", "e.csv"); }),
            "e.csv: empty file: expected a header row");
  EXPECT_NE(ErrorOf([] { CsvTable::Read("/nonexistent/x.csv"); }).find("cannot open"),
            std::string::npos);
}

TEST(Csv, WriterRoundTrips) {
  const std::string path = ::testing::TempDir() + "/csv_writer_test.csv";
  {
    CsvWriter w(path, {"time_s", "frame_C"});
    w.Row({0.0, 25.125});
    w.Row({0.1, std::nan("")});
    w.Close();
  }
  const auto t = CsvTable::Read(path);
  EXPECT_EQ(t.Column("time_s"), (std::vector<double>{0.0, 0.1}));
  EXPECT_EQ(t.ColumnAllowingNaN("frame_C")[0], 25.125);
  EXPECT_TRUE(std::isnan(t.ColumnAllowingNaN("frame_C")[1]));
}

}  // namespace
}  // namespace pumptherm::tools
