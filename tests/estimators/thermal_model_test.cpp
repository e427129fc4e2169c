// Thermal network: model-file validation, KCL assembly with Kron reduction (Saheba 2010 eq. S25),
// losses (eqs. 1-8), steady state against hand-solved networks.
#include "estimators/thermal_model.hpp"

#include <gtest/gtest.h>

#include <cmath>
#include <cstdlib>
#include <fstream>
#include <sstream>
#include <stdexcept>
#include <string>
#include <vector>

#include "tests/common/test_files.hpp"

namespace pe = pumptherm::estimators;

namespace {

using pumptherm::test_files::ReadModel;

// Two capacitive nodes a, b joined through a massless star node m, which leads to ambient:
//   a --R1-- m --R3-- ambient,  b --R2-- m.  Loss pa on a, pb on b.
// Solved by hand: Tm = Ta + (pa + pb) R3, Ta_node = Tm + pa R1, Tb = Tm + pb R2 (steady state);
// and in general m = (xa/R1 + xb/R2 + Ta/R3) / (1/R1 + 1/R2 + 1/R3) (KCL at m).
constexpr const char* kStar = R"(
[model]
name = "star"
[parameters]
pa = 10.0
[[node]]
name = "a"
capacity_J_per_K = 100
[[node]]
name = "b"
capacity_J_per_K = 50
[[node]]
name = "m"
capacity_J_per_K = 0
[[edge]]
between = ["a", "m"]
resistance_K_per_W = 0.5
[[edge]]
between = ["b", "m"]
resistance_K_per_W = -0.1
[[edge]]
between = ["m", "ambient"]
resistance_K_per_W = 2.0
[[loss]]
name = "a"
power_W = "pa"
shares = { a = 1 }
[[loss]]
name = "b"
power_W = "0.01 * speed_rpm"
shares = { b = 1 }
)";

std::string ExpectParseError(const std::string& text) {
  try {
    pe::ThermalModel::Parse(text, "test.toml");
  } catch (const pe::ThermalModelError& e) {
    return e.what();
  }
  ADD_FAILURE() << "no error for:\n" << text;
  return {};
}

}  // namespace

TEST(ThermalModel, StarNetworkSteadyStateMatchesHandSolution) {
  const auto m = pe::ThermalModel::Parse(kStar, "star");
  ASSERT_EQ(m.StateCount(), 2);
  pe::ThermalInputs in;
  in.speed_rpm = 500.0;  // pb = 5 W
  in.ambient_degC = 20.0;
  const Eigen::VectorXd x = m.SteadyState_degC(in);
  const double tm = 20.0 + (10.0 + 5.0) * 2.0;
  EXPECT_NEAR(x(0), tm + 10.0 * 0.5, 1e-9);
  EXPECT_NEAR(x(1), tm + 5.0 * -0.1, 1e-9);
  const Eigen::VectorXd all = m.AllTemperatures_degC(in, x);
  EXPECT_NEAR(all(2), tm, 1e-9);
}

TEST(ThermalModel, ReducedModelEqualsFullNetworkWithMasslessNode) {
  const auto m = pe::ThermalModel::Parse(kStar, "star");
  pe::ThermalInputs in;
  in.speed_rpm = 300.0;
  in.ambient_degC = 15.0;
  pe::ThermalLinearModel lin;
  m.Linearise(in, lin);
  const double r1 = 0.5, r2 = -0.1, r3 = 2.0, pa = 10.0, pb = 3.0;
  for (const auto& [xa, xb] :
       {std::pair{30.0, 40.0}, std::pair{-5.0, 80.0}, std::pair{15.0, 15.0}}) {
    // Full network: solve KCL at the massless node, then the capacitive nodes' balances.
    const double zm = (xa / r1 + xb / r2 + in.ambient_degC / r3) / (1 / r1 + 1 / r2 + 1 / r3);
    const double dxa = ((zm - xa) / r1 + pa) / 100.0;
    const double dxb = ((zm - xb) / r2 + pb) / 50.0;
    const Eigen::Vector2d x(xa, xb);
    const Eigen::VectorXd dx = lin.a_per_s * x + lin.f_K_per_s;
    EXPECT_NEAR(dx(0), dxa, 1e-12);
    EXPECT_NEAR(dx(1), dxb, 1e-12);
    EXPECT_NEAR(m.AllTemperatures_degC(in, x)(2), zm, 1e-12);
  }
}

TEST(ThermalModel, ShippedSahebaModelsHaveThePaperNodes) {
  for (const char* name : {"saheba2010-baseline", "saheba2010-improved"}) {
    const auto m = pe::ThermalModel::Parse(ReadModel(name), name);
    EXPECT_EQ(m.Name(), name);
    const std::vector<std::string> states{"frame",       "yoke",  "teeth", "slot_winding",
                                          "end_winding", "rotor", "shaft"};
    EXPECT_EQ(m.StateNames(), states);
    EXPECT_EQ(m.Nodes().size(), 13u);
    EXPECT_FALSE(m.ResistancesVary());
    EXPECT_DOUBLE_EQ(m.WindingWeights()(3), 0.5);
    EXPECT_DOUBLE_EQ(m.WindingWeights()(4), 0.5);
  }
  EXPECT_DOUBLE_EQ(
      pe::ThermalModel::Parse(ReadModel("saheba2010-improved"), "i").Capacities_J_per_K()(0),
      4478.0);
}

TEST(ThermalModel, SahebaSteadyStateBalancesEnergyThroughTheFrame) {
  // In steady state every watt leaves through R1a (the only edge to ambient): an oracle that
  // checks the whole reduced 13-node network, the losses and the copper law together.
  const auto m = pe::ThermalModel::Parse(ReadModel("saheba2010-improved"), "improved");
  pe::ThermalInputs in;
  in.speed_rpm = 800.0;
  in.iq_A = 50.0;
  in.ambient_degC = 22.0;
  const Eigen::VectorXd x = m.SteadyState_degC(in);
  const double total_loss_W = m.NodeLosses_W(in, x).sum();
  EXPECT_NEAR((x(0) - 22.0) / 0.1884, total_loss_W, 1e-8 * total_loss_W);
  // Copper loss per eq. 1-3 at the steady winding temperatures.
  const double r_ohm = 0.022 * (1.0 + 0.00393 * ((x(3) + x(4)) / 2.0 - 22.0));
  const double w_e = 6.0 * 800.0 * 2.0 * M_PI / 60.0;
  const double p_fe = 2.0e-5 * w_e * w_e + 0.012 * w_e;
  EXPECT_NEAR(total_loss_W, 1.5 * 50.0 * 50.0 * r_ohm + p_fe, 1e-9 * total_loss_W);
  // Every state above ambient, the windings the hottest (Fig. 4 shape).
  for (int i = 0; i < 7; ++i) EXPECT_GT(x(i), 22.0) << i;
  EXPECT_GT(x(3), x(0));
}

TEST(ThermalModel, CopperLossFollowsTheTemperatureOfItsNodes) {
  const auto m = pe::ThermalModel::Parse(ReadModel("saheba2010-baseline"), "baseline");
  pe::ThermalInputs in;
  in.id_A = 30.0;
  in.iq_A = 40.0;  // |i| = 50 A, i2 = 3750 A^2
  in.ambient_degC = 20.0;
  Eigen::VectorXd x = Eigen::VectorXd::Constant(7, 20.0);
  x(3) = 60.0;
  x(4) = 80.0;
  const Eigen::VectorXd p = m.NodeLosses_W(in, x);
  const double p_cu = 3750.0 * 0.022 * (1.0 + 0.00393 * 50.0);
  EXPECT_NEAR(p(3), 0.6 * p_cu, 1e-9);
  EXPECT_NEAR(p(4), 0.4 * p_cu, 1e-9);
  EXPECT_NEAR(p(1) + p(2), 0.0, 1e-12);  // standstill: no iron loss
}

TEST(ThermalModel, WallscheidModelWithoutFileReaderNamesTheTable) {
  try {
    pe::ThermalModel::Parse(ReadModel("wallscheid2017-4node"), "w");
    ADD_FAILURE() << "expected ThermalModelError";
  } catch (const pe::ThermalModelError& e) {
    EXPECT_NE(std::string(e.what()).find("table 'total_loss_W'"), std::string::npos) << e.what();
  }
}

TEST(ThermalModel, WallscheidModelParsesWithSpeedDependentResistances) {
  const std::string models = pumptherm::test_files::ReferenceModelDir();
  const std::string map =
      models + "/../../../../shared/reference/wallscheid-losses/total_loss_W.csv";
  if (!std::ifstream(map).good()) {
    GTEST_SKIP() << "the Wallscheid loss map is not at " << map
                 << " (it stays outside the project; see docs/thermal-model.md)";
  }
  const pe::ThermalModelFiles files{models, &pumptherm::test_files::ReadFile};
  const auto m = pe::ThermalModel::Parse(ReadModel("wallscheid2017-4node"), "w", files);
  const std::vector<std::string> states{"pm", "stator_yoke", "stator_tooth", "stator_winding"};
  EXPECT_EQ(m.StateNames(), states);
  EXPECT_TRUE(m.UsesCoolant());
  EXPECT_TRUE(m.ResistancesVary());
}

TEST(ThermalModelValidation, NegativeCapacityNamesNodeAndLine) {
  std::string t = kStar;
  t.replace(t.find("capacity_J_per_K = 50"), 21, "capacity_J_per_K = -5");
  const std::string e = ExpectParseError(t);
  EXPECT_NE(e.find("node 'b'"), std::string::npos) << e;
  EXPECT_NE(e.find("test.toml:11"), std::string::npos) << e;
}

TEST(ThermalModelValidation, UnknownNodeInEdgeNamesTheEdge) {
  std::string t = kStar;
  t.replace(t.find("[\"b\", \"m\"]"), 10, "[\"b\", \"q\"]");
  const std::string e = ExpectParseError(t);
  EXPECT_NE(e.find("edge b-q"), std::string::npos) << e;
  EXPECT_NE(e.find("unknown node 'q'"), std::string::npos) << e;
}

TEST(ThermalModelValidation, DisconnectedNodeIsNamed) {
  const std::string e =
      ExpectParseError(std::string(kStar) + "[[node]]\nname = \"lonely\"\ncapacity_J_per_K = 1\n");
  EXPECT_NE(e.find("node 'lonely'"), std::string::npos) << e;
  EXPECT_NE(e.find("not connected"), std::string::npos) << e;
}

TEST(ThermalModelValidation, IslandWithoutBoundaryIsNamed) {
  const std::string e =
      ExpectParseError(std::string(kStar) +
                       "[[node]]\nname = \"c\"\ncapacity_J_per_K = 1\n"
                       "[[node]]\nname = \"d\"\ncapacity_J_per_K = 1\n"
                       "[[edge]]\nbetween = [\"c\", \"d\"]\nresistance_K_per_W = 1\n");
  EXPECT_NE(e.find("node 'c'"), std::string::npos) << e;
  EXPECT_NE(e.find("no path to a boundary"), std::string::npos) << e;
}

TEST(ThermalModelValidation, SingularMasslessSubNetworkIsNamed) {
  // m2's conductances cancel: +1 W/K to a, -1 W/K to ambient, so its KCL row of Y22 is zero.
  const std::string e =
      ExpectParseError(std::string(kStar) +
                       "[[node]]\nname = \"m2\"\ncapacity_J_per_K = 0\n"
                       "[[edge]]\nbetween = [\"m2\", \"a\"]\nresistance_K_per_W = 1\n"
                       "[[edge]]\nbetween = [\"m2\", \"ambient\"]\nresistance_K_per_W = -1\n");
  EXPECT_NE(e.find("'m2'"), std::string::npos) << e;
  EXPECT_NE(e.find("singular"), std::string::npos) << e;
}

TEST(ThermalModelValidation, NegativeResistanceIsLegal) {
  EXPECT_NO_THROW(pe::ThermalModel::Parse(kStar, "star"));  // b-m is -0.1 K/W
}

TEST(ThermalModelValidation, UnknownKeyAndBadExpressionAreNamed) {
  std::string t = kStar;
  t.replace(t.find("resistance_K_per_W = 2.0"), 24, "resistence_K_per_W = 2.0");
  std::string e = ExpectParseError(t);
  EXPECT_NE(e.find("unknown key 'resistence_K_per_W'"), std::string::npos) << e;
  t = kStar;
  t.replace(t.find("\"0.01 * speed_rpm\""), 18, "\"0.01 * sped_rpm\"");
  e = ExpectParseError(t);
  EXPECT_NE(e.find("power_W"), std::string::npos) << e;
  EXPECT_NE(e.find("sped_rpm"), std::string::npos) << e;
  e = ExpectParseError("[[node]]\nname = \"a\"\ncapacity_J_per_K = 1\n[[edge\n");
  EXPECT_NE(e.find("test.toml:4"), std::string::npos) << e;
}

TEST(ThermalModel, NonFiniteInputsAreRejected) {
  const auto m = pe::ThermalModel::Parse(kStar, "star");
  pe::ThermalInputs in;
  in.iq_A = std::nan("");
  pe::ThermalLinearModel lin;
  EXPECT_THROW(m.Linearise(in, lin), std::domain_error);
}

TEST(ThermalModelOperatingRange, ShippedModelsStateTheirTypicalOperation) {
  const auto tmp = pe::ThermalModel::Parse(ReadModel("tmp-generic"), "tmp-generic");
  ASSERT_NE(tmp.OperatingRange(), nullptr);
  EXPECT_EQ(tmp.OperatingRange()->speed_rpm, 21000.0);
  EXPECT_EQ(tmp.OperatingRange()->iq_A, (std::vector<double>{1.0, 2.5, 4.5}));
  EXPECT_EQ(tmp.OperatingRange()->scale_current_A, 3.0);
  const auto saheba = pe::ThermalModel::Parse(ReadModel("saheba2010-improved"), "saheba");
  ASSERT_NE(saheba.OperatingRange(), nullptr);
  EXPECT_EQ(saheba.OperatingRange()->iq_A, (std::vector<double>{40.0, 52.5, 65.0}));
  const auto star = pe::ThermalModel::Parse(kStar, "star");
  EXPECT_EQ(star.OperatingRange(), nullptr);
}

TEST(ThermalModelOperatingRange, ScaleCurrentDefaultsToTheLargestCurrent) {
  const auto m = pe::ThermalModel::Parse(
      std::string("[operating_range]\nspeed_rpm = 100\niq_A = [1.0, -7.5, 2.0]\n") + kStar, "s");
  ASSERT_NE(m.OperatingRange(), nullptr);
  EXPECT_EQ(m.OperatingRange()->scale_current_A, 7.5);
}

TEST(ThermalModelOperatingRange, BadValuesNameTheTableAndLine) {
  auto error = [](const std::string& table) {
    try {
      pe::ThermalModel::Parse(table + kStar, "m.toml");
    } catch (const pe::ThermalModelError& e) {
      return std::string(e.what());
    }
    return std::string("no error");
  };
  EXPECT_NE(error("[operating_range]\nspeed_rpm = -1\niq_A = [1.0]\n")
                .find("m.toml:1: [operating_range]: speed_rpm"),
            std::string::npos)
      << error("[operating_range]\nspeed_rpm = -1\niq_A = [1.0]\n");
  EXPECT_NE(error("[operating_range]\nspeed_rpm = 5\niq_A = []\n").find("iq_A must be an array"),
            std::string::npos);
  EXPECT_NE(error("[operating_range]\nspeed_rpm = 5\niq_A = [0.0]\n").find("non-zero current"),
            std::string::npos);
  EXPECT_NE(
      error("[operating_range]\nspeed_rpm = 5\niq_A = [1.0]\nrpm = 3\n").find("unknown key 'rpm'"),
      std::string::npos)
      << error("[operating_range]\nspeed_rpm = 5\niq_A = [1.0]\nrpm = 3\n");
}

namespace {

// Losses of every kind of dependence: the currents alone (with a temperature coefficient), the
// speed alone, both through a quantity, a node temperature, the ambient; `cooling` is the
// cooling edge's resistance (a number, or an expression of the speed).
std::string LossRateModel(const std::string& cooling) {
  return R"toml(
[parameters]
r0 = 0.3
[[quantity]]
name = "shaft_W"
value = "0.002 * speed_rad_per_s * abs(iq_A)"
[[node]]
name = "frame"
capacity_J_per_K = 150
[[node]]
name = "winding"
capacity_J_per_K = 20
[[node]]
name = "rotor"
capacity_J_per_K = 200
[[edge]]
between = ["frame", "ambient"]
resistance_K_per_W = )toml" +
         cooling + R"toml(
[[edge]]
between = ["winding", "frame"]
resistance_K_per_W = 1.0
[[edge]]
between = ["rotor", "frame"]
resistance_K_per_W = 5.0
[[loss]]
name = "copper"
power_W = "r0 * i2_A2"
temperature_coefficient_per_K = 0.004
temperature_nodes = ["winding"]
reference_C = 20
shares = { winding = 1 }
[[loss]]
name = "iron"
power_W = "1e-3 * speed_rpm + 2"
shares = { frame = 0.7, winding = 0.3 }
[[loss]]
name = "rotor"
power_W = "shaft_W + 0.5"
shares = { rotor = 1 }
[[loss]]
name = "bearing"
power_W = "0.01 * rotor_C * speed_rpm / 1000 + 0.1 * abs(id_A)"
shares = { rotor = 0.5, frame = 0.5 }
[[loss]]
name = "drive"
power_W = "0.05 * (ambient_C - 10) * is_A"
shares = { frame = 1 }
)toml";
}

// (a x + f) at `in` (the network's dx/dt at x, K/s).
Eigen::VectorXd NetworkRate_K_per_s(const pe::ThermalModel& m, const pe::ThermalInputs& in,
                                    const Eigen::VectorXd& x) {
  pe::ThermalLinearModel lin;
  m.Linearise(in, x, lin);
  return lin.a_per_s * x + lin.f_K_per_s;
}

}  // namespace

TEST(ThermalModel, LossRatesAreTheRatesAtStandstillAndAtRestDifferenced) {
  for (const std::string cooling : {"0.6", "\"0.6 / (1 + speed_rpm / 30000)\""}) {
    const auto m = pe::ThermalModel::Parse(LossRateModel(cooling), "loss_rates.toml");
    EXPECT_EQ(m.ResistancesVary(), cooling != "0.6");
    const Eigen::Vector3d x(41.0, 73.5, 58.25);
    for (const double speed : {21000.0, -9000.0, 0.0}) {
      pe::ThermalInputs in;
      in.speed_rpm = speed;
      in.id_A = -0.7;
      in.iq_A = 3.2;
      in.ambient_degC = 23.0;
      pe::ThermalInputs still = in;
      still.speed_rpm = 0.0;
      pe::ThermalInputs rest = still;
      rest.id_A = rest.iq_A = 0.0;
      pe::ThermalLinearModel lin;
      pe::ThermalLossRates rates;
      m.Linearise(in, x, lin, rates);
      const Eigen::VectorXd current =
          NetworkRate_K_per_s(m, still, x) - NetworkRate_K_per_s(m, rest, x);
      const Eigen::VectorXd speed_part =
          NetworkRate_K_per_s(m, in, x) - NetworkRate_K_per_s(m, still, x);
      const std::string where = "cooling " + cooling + ", " + std::to_string(speed) + " r/min";
      for (int i = 0; i < 3; ++i) {
        EXPECT_NEAR(rates.current_K_per_s(i), current(i), 1e-13) << where << ", state " << i;
        EXPECT_NEAR(rates.speed_K_per_s(i), speed_part(i), 1e-13) << where << ", state " << i;
      }
      // The linearisation itself is the one Linearise(in, x, lin) gives.
      pe::ThermalLinearModel alone;
      m.Linearise(in, x, alone);
      EXPECT_EQ(lin.a_per_s, alone.a_per_s) << where;
      EXPECT_EQ(lin.f_K_per_s, alone.f_K_per_s) << where;
      if (speed != 0.0) {
        EXPECT_GT(speed_part.norm(), 1e-4) << where;
      }
      EXPECT_GT(current.norm(), 1e-4) << where;
    }
  }
}

TEST(ThermalModel, ALinearisationAtTheSameInputsIsTheSameAfterAnotherOne) {
  // Kept from the last call only where it depends on the inputs alone (kStar)...
  const auto star = pe::ThermalModel::Parse(kStar, "star.toml");
  pe::ThermalInputs a, b;
  a.speed_rpm = 1000.0;
  b.speed_rpm = 2000.0;
  pe::ThermalLinearModel first, other, again;
  star.Linearise(a, first);
  star.Linearise(b, other);
  star.Linearise(a, again);
  EXPECT_NE(first.f_K_per_s, other.f_K_per_s);
  EXPECT_EQ(first.a_per_s, again.a_per_s);
  EXPECT_EQ(first.f_K_per_s, again.f_K_per_s);
  // ...not where a loss reads a node temperature: the same inputs at another rotor temperature.
  const auto reads_rotor = pe::ThermalModel::Parse(LossRateModel("0.6"), "loss_rates.toml");
  const auto fresh = pe::ThermalModel::Parse(LossRateModel("0.6"), "loss_rates.toml");
  a.iq_A = 2.0;
  const Eigen::Vector3d cold(30.0, 40.0, 35.0), hot(30.0, 40.0, 95.0);
  reads_rotor.Linearise(a, cold, first);
  reads_rotor.Linearise(a, hot, again);
  fresh.Linearise(a, hot, other);
  EXPECT_NE(first.f_K_per_s, again.f_K_per_s);
  EXPECT_EQ(again.f_K_per_s, other.f_K_per_s);
}
