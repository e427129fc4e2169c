// The discrepancy workflow's effect vocabulary (estimators/model_effects.hpp): every effect yields
// a loadable model, the neutral value changes nothing, and each effect moves the steady state or
// the capacities the way its equation says.
#include "estimators/model_effects.hpp"

#include <gtest/gtest.h>

#include <cmath>
#include <cstdlib>
#include <fstream>
#include <sstream>
#include <stdexcept>
#include <string>

#include "estimators/thermal_model.hpp"
#include "tests/common/test_files.hpp"

namespace pe = pumptherm::estimators;

namespace {

using pumptherm::test_files::ReadModel;

// Tables that models name are read relative to the reference models' directory: only the
// Wallscheid model (kept there) names any.
pe::ThermalModelFiles Files() {
  return {pumptherm::test_files::ReferenceModelDir(), &pumptherm::test_files::ReadFile};
}

// The Wallscheid model needs its loss map, which stays outside the project.
bool TablesPresent(const std::string& name) {
  return name != "wallscheid2017-4node" ||
         std::ifstream(Files().directory +
                       "/../../../../shared/reference/wallscheid-losses/total_loss_W.csv")
             .good();
}

pe::ThermalInputs Load() {
  pe::ThermalInputs in;
  in.speed_rpm = 3000.0;
  in.iq_A = 40.0;
  in.ambient_degC = 25.0;
  in.coolant_degC = 40.0;
  return in;
}

pe::ThermalModel WithEffect(const std::string& text, const pe::Effect& e) {
  return pe::ThermalModel::Parse(pe::ApplyModelEffects(text, "test", {e}), "edited", Files());
}

}  // namespace

TEST(ModelEffects, TargetsOfTheShippedModels) {
  const pe::EffectTargets s = pe::FindEffectTargets(ReadModel("saheba2010-baseline"), "s");
  EXPECT_EQ(s.frame, "frame");
  EXPECT_EQ(s.rotor, "rotor");
  EXPECT_EQ(s.frame_edges.size(), 1u);
  EXPECT_EQ(s.winding_edge, 15);  // R46, slot_winding - end_winding
  EXPECT_EQ(s.copper_losses.size(), 1u);
  EXPECT_EQ(s.iron_losses.size(), 1u);
  EXPECT_EQ(s.cooling_edges, s.frame_edges);  // the frame is its only path to the ambient
  const pe::EffectTargets w = pe::FindEffectTargets(ReadModel("wallscheid2017-4node"), "w");
  EXPECT_EQ(w.frame, "stator_yoke");
  EXPECT_EQ(w.rotor, "pm");
  EXPECT_EQ(w.winding_edge, -1);  // one winding node
  // The cooling path: stator_yoke - coolant, pm - ambient, pm - coolant (the file's edges 3, 6, 7).
  EXPECT_EQ(w.cooling_edges, (std::vector<int>{3, 6, 7}));
  EXPECT_EQ(w.cooled, "stator_yoke, pm");
  EXPECT_FALSE(pe::EffectNotApplicable(*pe::FindEffect("winding_conductance"), w).empty());
}

// At the neutral value every effect leaves the steady state unchanged, on both shipped families.
TEST(ModelEffects, NeutralValuesChangeNothing) {
  for (const char* name : {"saheba2010-baseline", "wallscheid2017-4node"}) {
    if (!TablesPresent(name)) {
      GTEST_SKIP() << name
                   << ": its loss map is absent from ../shared/reference/wallscheid-losses/";
    }
    const std::string text = ReadModel(name);
    const pe::ThermalModel base = pe::ThermalModel::Parse(text, name, Files());
    const Eigen::VectorXd x0 = base.SteadyState_degC(Load());
    const pe::EffectTargets t = pe::FindEffectTargets(text, name);
    for (const pe::EffectSpec& spec : pe::EffectVocabulary()) {
      if (spec.sensor || !pe::EffectNotApplicable(spec, t).empty()) continue;
      const pe::ThermalModel m = WithEffect(text, {spec.name, {spec.parameters[0].neutral}, {}});
      EXPECT_LT((m.SteadyState_degC(Load()) - x0).cwiseAbs().maxCoeff(), 1e-9)
          << name << " " << spec.name;
      EXPECT_LT((m.Capacities_J_per_K() - base.Capacities_J_per_K()).cwiseAbs().maxCoeff(), 1e-9);
    }
  }
}

TEST(ModelEffects, EachEffectActsAsItsEquationSays) {
  const std::string text = ReadModel("saheba2010-baseline");
  const pe::ThermalModel base = pe::ThermalModel::Parse(text, "b");
  const Eigen::VectorXd x0 = base.SteadyState_degC(Load());
  const int frame = base.StateIndex("frame"), rotor = base.StateIndex("rotor");
  const int slot = base.StateIndex("slot_winding"), end = base.StateIndex("end_winding");

  // frame_thermal_mass: the frame capacity grows by exactly dC; steady state unchanged.
  const pe::ThermalModel m1 = WithEffect(text, {"frame_thermal_mass", {2680.2}, {}});
  EXPECT_NEAR(m1.Capacities_J_per_K()(frame), 1797.8 + 2680.2, 1e-9);
  EXPECT_LT((m1.SteadyState_degC(Load()) - x0).cwiseAbs().maxCoeff(), 1e-9);

  // frame_ambient_resistance: scale s on R1a = 0.2 K/W; with every loss leaving through R1a,
  // the frame's rise over ambient grows by (s - 1) * 0.2 K/W * total loss.
  const Eigen::VectorXd losses = base.NodeLosses_W(Load(), x0);
  const pe::ThermalModel m2 = WithEffect(text, {"frame_ambient_resistance", {1.5}, {}});
  const Eigen::VectorXd x2 = m2.SteadyState_degC(Load());
  const Eigen::VectorXd losses2 = m2.NodeLosses_W(Load(), x2);
  EXPECT_NEAR(x2(frame) - 25.0, 0.3 * losses2.sum(), 1e-6);
  EXPECT_NEAR(x0(frame) - 25.0, 0.2 * losses.sum(), 1e-6);

  // speed_dependent_cooling with gain g: R1a / (1 + g * 3) at 3000 r/min.
  const pe::ThermalModel m3 = WithEffect(text, {"speed_dependent_cooling", {0.5}, {}});
  const Eigen::VectorXd x3 = m3.SteadyState_degC(Load());
  EXPECT_NEAR(x3(frame) - 25.0, 0.2 / 2.5 * m3.NodeLosses_W(Load(), x3).sum(), 1e-6);

  // winding_conductance: a worse slot-end path warms the end winding relative to the slot.
  const pe::ThermalModel m4 = WithEffect(text, {"winding_conductance", {14.0}, {}});
  const Eigen::VectorXd x4 = m4.SteadyState_degC(Load());
  EXPECT_GT(x4(end) - x4(slot), x0(end) - x0(slot) + 0.1);

  // copper_temperature_coefficient: more copper loss when warmer than ambient.
  const pe::ThermalModel m5 = WithEffect(text, {"copper_temperature_coefficient", {0.002}, {}});
  EXPECT_GT(m5.SteadyState_degC(Load())(slot), x0(slot) + 0.1);

  // iron_loss_scale 2: twice the iron loss, all else equal at equal temperatures.
  const pe::ThermalModel m6 = WithEffect(text, {"iron_loss_scale", {2.0}, {}});
  const Eigen::VectorXd l6 = m6.NodeLosses_W(Load(), x0);
  const int yoke = 1, teeth = 2;  // file order
  EXPECT_NEAR(l6(yoke) + l6(teeth), 2.0 * (losses(yoke) + losses(teeth)), 1e-9);

  // rotor_loss k: k (n/1000)^2 W more on the rotor: 9 k at 3000 r/min.
  const pe::ThermalModel m7 = WithEffect(text, {"rotor_loss", {4.0}, {}});
  const Eigen::VectorXd l7 = m7.NodeLosses_W(Load(), x0);
  EXPECT_NEAR(l7(rotor) - losses(rotor), 36.0, 1e-9);
}

TEST(ModelEffects, EffectsCombineAndSensorEffectsAreParametersOnly) {
  const std::string text = ReadModel("saheba2010-baseline");
  const std::string edited = pe::ApplyModelEffects(text, "b",
                                                   {{"frame_thermal_mass", {1000.0}, {}},
                                                    {"iron_loss_scale", {1.3}, {}},
                                                    {"sensor_offset", {0.7}, "frame"}});
  const pe::ThermalModel m = pe::ThermalModel::Parse(edited, "edited");
  EXPECT_EQ(m.Name(), "saheba2010-baseline+effects");
  EXPECT_NE(edited.find("sensor_offset_K__frame = 0.69999"), std::string::npos) << edited;
  EXPECT_THROW(pe::ApplyModelEffects(
                   text, "b", {{"iron_loss_scale", {1.3}, {}}, {"iron_loss_scale", {1.1}, {}}}),
               pe::ThermalModelError);
  EXPECT_THROW(pe::ApplyModelEffects(text, "b", {{"no_such_effect", {1.0}, {}}}),
               pe::ThermalModelError);
  EXPECT_THROW(pe::ApplyModelEffects(ReadModel("wallscheid2017-4node"), "w",
                                     {{"winding_conductance", {2.0}, {}}}),
               pe::ThermalModelError);
}

// A first-order lag of a ramp T = s t settles to T - s tau (closed form), and the filter is
// exact for ramps whatever the step.
TEST(ModelEffects, SensorLagOfARampClosedForm) {
  const double tau = 40.0, s = 0.01;
  std::vector<double> t, y;
  for (int k = 0; k <= 100; ++k) {
    t.push_back(10.0 * k + (k % 3));  // uneven steps
    y.push_back(s * t.back());
  }
  std::vector<double> exact = y;
  pe::ApplySensorEffect({"sensor_lag", {tau}, "frame"}, t, y);
  for (std::size_t k = 0; k < t.size(); ++k) {
    const double expected = exact[k] - s * tau * (1.0 - std::exp(-(t[k] - t[0]) / tau));
    EXPECT_NEAR(y[k], expected, 1e-12) << k;
  }
  pe::ApplySensorEffect({"sensor_offset", {-0.5}, "frame"}, t, exact);
  EXPECT_NEAR(exact[10], s * t[10] - 0.5, 1e-12);
}
