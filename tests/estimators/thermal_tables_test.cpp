// Thermal model files with loss maps and curves ([[table]]), named quantities ([[quantity]]) and
// expressions that read node temperatures. Expected values are worked out by hand
// from the small tables below.
#include <gtest/gtest.h>

#include <cmath>
#include <map>
#include <stdexcept>
#include <string>

#include "estimators/thermal_model.hpp"

namespace pe = pumptherm::estimators;

namespace {

// Files by path, as the caller (a tool or the daemon) would read them.
pe::ThermalModelFiles Files(std::map<std::string, std::string> texts) {
  return {"/models", [texts](const std::string& path) {
            auto it = texts.find(path);
            if (it == texts.end())
              throw std::runtime_error("cannot read " + path + ": no such file");
            return it->second;
          }};
}

// Map over current (rows -10, 0, 10 A) and speed (columns 0, 1000 r/min, unit in the header).
constexpr const char* kMap =
    "current_A,0rpm,1000rpm\n"
    "-10,1,3\n"
    "0,0,2\n"
    "10,5,9\n";
constexpr const char* kCurve = "speed_rpm,drag\n0,0\n1000,10\n2000,30\n";

// One node to ambient through 1 K/W; its loss is the looked-up value.
std::string Model(const std::string& lookup, const std::string& power) {
  return "[[table]]\nname = \"loss_map\"\nkind = \"map\"\nfile = \"maps/loss.csv\"\nlookup = \"" +
         lookup +
         "\"\n"
         "[[table]]\nname = \"drag\"\nkind = \"curve\"\nfile = \"/abs/drag.csv\"\nlookup = "
         "\"linear\"\n"
         "[[quantity]]\nname = \"i_signed_A\"\nvalue = \"iq_A < 0 ? -is_A : is_A\"\n"
         "[[quantity]]\nname = \"n_abs_rpm\"\nvalue = \"abs(speed_rpm)\"\n"
         "[[node]]\nname = \"a\"\ncapacity_J_per_K = 10\n"
         "[[edge]]\nbetween = [\"a\", \"ambient\"]\nresistance_K_per_W = 1\n"
         "[[loss]]\nname = \"p\"\npower_W = \"" +
         power + "\"\nshares = { a = 1 }\n";
}

pe::ThermalModel Parse(const std::string& text) {
  return pe::ThermalModel::Parse(
      text, "m.toml", Files({{"/models/maps/loss.csv", kMap}, {"/abs/drag.csv", kCurve}}));
}

// Steady state of a single node to ambient at 0 degC through 1 K/W equals its loss in W.
double Loss(const pe::ThermalModel& m, double iq_A, double speed_rpm) {
  pe::ThermalInputs in;
  in.iq_A = iq_A;
  in.speed_rpm = speed_rpm;
  in.ambient_degC = 0.0;
  return m.SteadyState_degC(in)(0);
}

std::string ParseError(const std::string& text, const pe::ThermalModelFiles& files) {
  try {
    pe::ThermalModel::Parse(text, "m.toml", files);
  } catch (const pe::ThermalModelError& e) {
    return e.what();
  }
  ADD_FAILURE() << "expected ThermalModelError";
  return {};
}

}  // namespace

TEST(ThermalTables, MapNearestRoundsToTheGrid) {
  const auto m = Parse(Model("nearest", "loss_map(i_signed_A, n_abs_rpm)"));
  EXPECT_DOUBLE_EQ(Loss(m, 4.0, 400.0), 0.0);    // (0 A, 0 r/min)
  EXPECT_DOUBLE_EQ(Loss(m, 6.0, 600.0), 9.0);    // (10 A, 1000 r/min)
  EXPECT_DOUBLE_EQ(Loss(m, -6.0, -400.0), 1.0);  // (-10 A, 0 r/min): sign from iq, |n|
  EXPECT_DOUBLE_EQ(Loss(m, 5.0, 0.0), 5.0);      // a tie goes away from zero, as MATLAB's round
  EXPECT_DOUBLE_EQ(Loss(m, -5.0, 0.0), 1.0);
  EXPECT_DOUBLE_EQ(Loss(m, 50.0, 5000.0), 9.0);  // outside the grid: the edge value
}

TEST(ThermalTables, MapLinearInterpolatesBilinearly) {
  const auto m = Parse(Model("linear", "loss_map(i_signed_A, n_abs_rpm)"));
  // (5 A, 500 r/min): mean of 0, 2, 5, 9.
  EXPECT_NEAR(Loss(m, 5.0, 500.0), 4.0, 1e-12);
  // (-2.5 A, 250 r/min): rows -10 and 0 weighted 0.25/0.75, columns 0.75/0.25.
  const double row_m10 = 0.75 * 1.0 + 0.25 * 3.0, row_0 = 0.75 * 0.0 + 0.25 * 2.0;
  EXPECT_NEAR(Loss(m, -2.5, 250.0), 0.25 * row_m10 + 0.75 * row_0, 1e-12);
}

TEST(ThermalTables, CurveInterpolatesLinearlyAndHoldsTheEnds) {
  const auto m = Parse(Model("linear", "drag(n_abs_rpm)"));
  EXPECT_NEAR(Loss(m, 0.0, 1500.0), 20.0, 1e-12);
  EXPECT_NEAR(Loss(m, 0.0, -250.0), 2.5, 1e-12);
  EXPECT_NEAR(Loss(m, 0.0, 9000.0), 30.0, 1e-12);
}

TEST(ThermalTables, NodeTemperatureInALossIsReadAtTheGivenState) {
  // p = 2 (1 + 0.01 (T_a - 20))^-2: evaluated at the state handed to Linearise, held over the step.
  const auto m = Parse(Model("linear", "2 * (1 + 0.01 * (a_C - 20))^-2"));
  EXPECT_TRUE(m.UsesNodeTemperatures());
  pe::ThermalInputs in;
  in.ambient_degC = 0.0;
  pe::ThermalLinearModel lin;
  m.Linearise(in, Eigen::VectorXd::Constant(1, 120.0), lin);  // (1 + 1)^-2 = 0.25
  EXPECT_NEAR(lin.f_K_per_s(0), 2.0 * 0.25 / 10.0, 1e-12);
  EXPECT_NEAR(lin.a_per_s(0, 0), -1.0 / 10.0, 1e-12);
  m.Linearise(in, Eigen::VectorXd::Constant(1, 20.0), lin);
  EXPECT_NEAR(lin.f_K_per_s(0), 2.0 / 10.0, 1e-12);
  EXPECT_THROW(m.Linearise(in, Eigen::VectorXd::Constant(1, std::nan("")), lin), std::domain_error);
}

TEST(ThermalTables, ModelsWithoutNodeTemperaturesSaySo) {
  EXPECT_FALSE(Parse(Model("linear", "drag(n_abs_rpm)")).UsesNodeTemperatures());
}

TEST(ThermalTablesValidation, BadCellNamesTableFileLineAndColumn) {
  const std::string e =
      ParseError(Model("linear", "1"),
                 Files({{"/models/maps/loss.csv", "current_A,0rpm,1000rpm\n-10,1,3\n0,zero,2\n"},
                        {"/abs/drag.csv", kCurve}}));
  EXPECT_NE(e.find("m.toml:1"), std::string::npos) << e;
  EXPECT_NE(e.find("table 'loss_map'"), std::string::npos) << e;
  EXPECT_NE(e.find("/models/maps/loss.csv:3: column 2"), std::string::npos) << e;
}

TEST(ThermalTablesValidation, UnreadableFileIsNamed) {
  const std::string e = ParseError(Model("linear", "1"), Files({{"/abs/drag.csv", kCurve}}));
  EXPECT_NE(e.find("table 'loss_map'"), std::string::npos) << e;
  EXPECT_NE(e.find("/models/maps/loss.csv"), std::string::npos) << e;
}

TEST(ThermalTablesValidation, AxisMustIncrease) {
  const std::string e =
      ParseError(Model("linear", "1"),
                 Files({{"/models/maps/loss.csv", kMap}, {"/abs/drag.csv", "n,d\n0,0\n0,1\n"}}));
  EXPECT_NE(e.find("table 'drag'"), std::string::npos) << e;
  EXPECT_NE(e.find("increase strictly"), std::string::npos) << e;
}

TEST(ThermalTablesValidation, UnknownLookupRuleIsNamed) {
  const std::string e = ParseError(Model("cubic", "1"), Files({}));
  EXPECT_NE(e.find("lookup must be"), std::string::npos) << e;
}

TEST(ThermalTablesValidation, ExpressionErrorNamesKeyAndPosition) {
  const std::string e =
      ParseError(Model("linear", "drag(n_abs_rpm) + bogus_W"),
                 Files({{"/models/maps/loss.csv", kMap}, {"/abs/drag.csv", kCurve}}));
  EXPECT_NE(e.find("key 'power_W'"), std::string::npos) << e;
  EXPECT_NE(e.find("bogus_W"), std::string::npos) << e;
  EXPECT_NE(e.find("position 19"), std::string::npos) << e;
}

TEST(ThermalTablesValidation, QuantityNameClashIsAnError) {
  std::string t = Model("linear", "1");
  t.replace(t.find("name = \"n_abs_rpm\""), 18, "name = \"speed_rpm\"");
  const std::string e =
      ParseError(t, Files({{"/models/maps/loss.csv", kMap}, {"/abs/drag.csv", kCurve}}));
  EXPECT_NE(e.find("quantity 'speed_rpm'"), std::string::npos) << e;
}
