// The disturbance-state virtual sensor on simulated pumps (tests/bench/mismatch_cases.hpp):
// the frame alone, a fault from one hour on. What it must do: keep every node's truth inside its
// +-2 sd (coverage >= 90 %) on a healthy pump and when the frame path changes, and keep the nodes
// within 3 K when the cooling is lost. With the magnet temperature from the flux (emulated: the
// truth's rotor, white noise and a slow bias) the coverage must hold too, and heat inside the
// rotor must be found.
#include "estimators/disturbance_sensor.hpp"

#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <cstdlib>
#include <string>

#include "tests/bench/mismatch_cases.hpp"

namespace pe = pumptherm::estimators;
namespace mc = mismatch_cases;

namespace {

std::string SensorModelDir() {
  const char* src = std::getenv("PUMPTHERM_SOURCE_DIR");
  return std::string(src != nullptr ? src : PUMPTHERM_SOURCE_DIR) + "/estimators/models";
}

mc::CaseResult RunSensorFault(mc::Fault fault, std::uint64_t seed, double magnet_white_sd_K = 0.0,
                              double magnet_bias_sd_K = 0.0, pe::DisturbanceSensorConfig dc = {}) {
  mc::CaseSpec spec;
  spec.magnet_noise_sd_K = magnet_white_sd_K;
  spec.magnet_bias_sd_K = magnet_bias_sd_K;
  spec.fault = fault;
  spec.duration_s = 3600.0 + 2400.0;
  spec.fault_s = fault == mc::Fault::kNone ? spec.duration_s + 1.0 : 3600.0;
  spec.seed = seed;
  return mc::RunCase(spec, SensorModelDir(), {}, dc);
}

/// Index of node `name` in the result (r.nodes.size() when absent).
std::size_t NodeIndex(const mc::CaseResult& r, const std::string& name) {
  return static_cast<std::size_t>(std::find(r.nodes.begin(), r.nodes.end(), name) -
                                  r.nodes.begin());
}

std::size_t Rotor(const mc::CaseResult& r) { return NodeIndex(r, "rotor"); }

/// Every node of the disturbance filter covered >= 90 % of the time and within `max_error_K`.
void ExpectEveryNodeCoveredWithin(const mc::CaseResult& r, double max_error_K) {
  for (std::size_t i = 0; i < r.nodes.size(); ++i) {
    EXPECT_GE(r.dist_coverage[i], 0.9) << r.nodes[i];
    EXPECT_LE(r.dist_max_error_K[i], max_error_K) << r.nodes[i];
  }
}

TEST(DisturbanceSensor, CoversTheTruthOnAHealthyPump) {
  ExpectEveryNodeCoveredWithin(RunSensorFault(mc::Fault::kNone, 21), 1.5);
}

TEST(DisturbanceSensor, LostCoolingGoesIntoTheFramePathHeat) {
  const mc::CaseResult r = RunSensorFault(mc::Fault::kCoolingLost, 22);
  for (std::size_t i = 0; i < r.nodes.size(); ++i) {
    EXPECT_GE(r.dist_coverage[i], 0.9) << r.nodes[i];
    EXPECT_LE(r.dist_max_error_K[i], 3.0) << r.nodes[i];
    // The published filter (eq. 39's noise on every node) is confidently wrong here.
    EXPECT_LT(r.coverage[i], 0.9) << r.nodes[i];
  }
}

TEST(DisturbanceSensor, HeatInsideTheRotorShowsInItsSd) {
  // The frame barely sees it: the rotor is off by many kelvin, but its sd says so.
  const mc::CaseResult r = RunSensorFault(mc::Fault::kRotorLoss, 23);
  const std::size_t rotor = Rotor(r);
  ASSERT_LT(rotor, r.nodes.size());
  EXPECT_GT(r.dist_max_error_K[rotor], 5.0);
  EXPECT_GE(r.dist_coverage[rotor], 0.9);
}

TEST(DisturbanceSensor, UnseenRotorHeatIsCoveredOnceNamedInside) {
  // Not the matrix's +6 W step at 21000 r/min: 15 W at 15000 r/min from 30 min on. The rotor
  // runs about 43 K above its estimate; the filter's own rotor sd (about 15 K) covered it 7-8 %
  // of the time. Once the mismatch test names heat inside, the published sd reaches the nodes as
  // if the frame-path heat found since the onset were on the rotor (InsideHeatBound).
  auto run = [](bool bound) {
    mc::CaseSpec spec;
    spec.fault = mc::Fault::kRotorHeat;
    spec.rotor_heat_W = 15.0;
    spec.speed_rpm = 15000.0;
    spec.fault_s = 1800.0;
    spec.duration_s = 1800.0 + 3600.0;
    spec.seed = 29;
    spec.inside_heat_bound = bound;
    return mc::RunCase(spec, SensorModelDir());
  };
  const mc::CaseResult without = run(false);
  EXPECT_LT(without.dist_coverage_after_fault[Rotor(without)], 0.9)
      << "max error " << without.dist_max_error_after_fault_K[Rotor(without)] << " K";
  const mc::CaseResult r = run(true);
  ASSERT_LT(Rotor(r), r.nodes.size());
  EXPECT_GT(r.dist_max_error_after_fault_K[Rotor(r)], 20.0);  // still far off, but says so
  for (std::size_t i = 0; i < r.nodes.size(); ++i) {
    EXPECT_GE(r.dist_coverage_after_fault[i], 0.9)
        << r.nodes[i] << " max error " << r.dist_max_error_after_fault_K[i] << " K";
  }
}

TEST(DisturbanceSensor, MoreLossesStayCovered) {
  // The frame puts most of the losses' heat on the frame path (the winding is 8-9 K low), but the
  // loss scale's sd says so.
  const mc::CaseResult r = RunSensorFault(mc::Fault::kLosses40, 26);
  for (std::size_t i = 0; i < r.nodes.size(); ++i) EXPECT_GE(r.dist_coverage[i], 0.9) << r.nodes[i];
}

TEST(DisturbanceSensor, TheInteriorSdStaysBoundedAtAConstantLoad) {
  // A load that never changes does not tell the losses' scale from frame-path heat: as a random
  // walk the scale's sd, and the winding's with it, grew as sqrt(t) (21.7 K after a day at 4.5 A,
  // a healthy pump's x + 2 sd at a trip level), the estimate within 0.3 K all along.
  auto largest_winding_sd_K = [](double duration_s) {
    mc::CaseSpec spec;
    spec.constant_iq_A = 4.5;
    spec.duration_s = duration_s;
    spec.fault_s = duration_s + 1.0;
    spec.seed = 27;
    const mc::CaseResult r = mc::RunCase(spec, SensorModelDir());
    const std::size_t w = NodeIndex(r, "winding");
    EXPECT_GE(r.dist_coverage[w], 0.9);
    EXPECT_LE(r.dist_max_error_K[w], 1.0);
    return r.dist_max_sd_K[w];
  };
  const double half_day = largest_winding_sd_K(43200.0);
  const double day = largest_winding_sd_K(86400.0);
  EXPECT_LT(day, 1.05 * half_day) << "half a day " << half_day << " K, a day " << day << " K";
  EXPECT_LT(day, 10.0);
}

TEST(DisturbanceSensor, TheFluxReadingsSlowBiasIsNotAveragedAway) {
  // A reading with a 2 K slow bias, fused every second: with the bias state every node stays
  // covered; taken as white noise (no bias state), the filter averages it and the rotor's sd
  // becomes far smaller than its error.
  const mc::CaseResult r = RunSensorFault(mc::Fault::kNone, 1, 1.0, 2.0);
  for (std::size_t i = 0; i < r.nodes.size(); ++i) {
    EXPECT_GE(r.dist_coverage[i], 0.9)
        << r.nodes[i] << " max error " << r.dist_max_error_K[i] << " K";
  }
  pe::DisturbanceSensorConfig white;
  white.magnet_bias_sd_K = 0.0;
  const mc::CaseResult w = RunSensorFault(mc::Fault::kNone, 1, 1.0, 2.0, white);
  EXPECT_LT(w.dist_coverage[Rotor(w)], 0.9) << "max error " << w.dist_max_error_K[Rotor(w)] << " K";
}

TEST(DisturbanceSensor, TheFluxReadingFindsHeatInsideTheRotor) {
  // From the frame alone +6 W on the rotor leaves it more than 5 K off (above); a rotor reading
  // with 3 K of white noise and a 0.5 K bias brings it within 3 K, every node covered.
  const mc::CaseResult r = RunSensorFault(mc::Fault::kRotorLoss, 23, 3.0, 0.5);
  ASSERT_LT(Rotor(r), r.nodes.size());
  EXPECT_LE(r.dist_max_error_K[Rotor(r)], 3.0);
  for (std::size_t i = 0; i < r.nodes.size(); ++i) {
    EXPECT_GE(r.dist_coverage[i], 0.9)
        << r.nodes[i] << " max error " << r.dist_max_error_K[i] << " K";
  }
}

TEST(DisturbanceSensor, LostCoolingWithTheFluxReadingStaysCovered) {
  const mc::CaseResult r = RunSensorFault(mc::Fault::kCoolingLost, 22, 1.0, 2.0);
  for (std::size_t i = 0; i < r.nodes.size(); ++i) {
    EXPECT_GE(r.dist_coverage[i], 0.9)
        << r.nodes[i] << " max error " << r.dist_max_error_K[i] << " K";
  }
}

TEST(DisturbanceSensor, RejectsAnUnknownNode) {
  const auto model =
      pe::ThermalModel::Parse(mc::ReadFile(SensorModelDir() + "/tmp-generic.toml"), "tmp-generic");
  pe::DisturbanceSensorConfig c;
  c.measured_node = "lid";
  EXPECT_THROW(pe::DisturbanceThermalSensor(model, c), std::invalid_argument);
  pe::DisturbanceSensorConfig m;
  m.magnet_node = "magnet_of_another_motor";
  EXPECT_THROW(pe::DisturbanceThermalSensor(model, m), std::invalid_argument);
}

// The rule of the daemon's default: the frame-path heat stands for a change of the cooling path
// only when the boundary reaches the network through the measured node alone.
TEST(DisturbanceSensor, BoundaryOnlyThroughTheMeasuredNode) {
  for (const char* name : {"tmp-generic", "saheba2010-baseline", "saheba2010-improved"}) {
    const auto model =
        pe::ThermalModel::Parse(mc::ReadFile(SensorModelDir() + "/" + name + ".toml"), name);
    EXPECT_TRUE(pe::BoundaryOnlyThrough(model, "frame")) << name;
    EXPECT_FALSE(pe::BoundaryOnlyThrough(model, "rotor")) << name;
    EXPECT_FALSE(pe::BoundaryOnlyThrough(model, "lid")) << name;
  }
  const std::string two_nodes =
      "[model]\nname = \"two\"\n"
      "[[node]]\nname = \"frame\"\ncapacity_J_per_K = 1000\n"
      "[[node]]\nname = \"rotor\"\ncapacity_J_per_K = 100\n"
      "[[edge]]\nbetween = [\"frame\", \"ambient\"]\nresistance_K_per_W = 0.5\n"
      "[[edge]]\nbetween = [\"frame\", \"rotor\"]\nresistance_K_per_W = 1.0\n";
  EXPECT_TRUE(pe::BoundaryOnlyThrough(pe::ThermalModel::Parse(two_nodes, "two"), "frame"));
  // The rotor with its own path to the ambient, as the magnet of wallscheid2017-4node.
  const std::string rotor_cooled =
      two_nodes + "[[edge]]\nbetween = [\"rotor\", \"ambient\"]\nresistance_K_per_W = 2.0\n";
  EXPECT_FALSE(
      pe::BoundaryOnlyThrough(pe::ThermalModel::Parse(rotor_cooled, "rotor-cooled"), "frame"));
}

// Another shipped model the daemon may run (its faults as effects of the discrepancy vocabulary).
TEST(DisturbanceSensor, LostCoolingOnTheSahebaMachineStaysCovered) {
  mc::CaseSpec spec;
  spec.model = "saheba2010-improved";
  spec.fault = mc::Fault::kCoolingLost;
  spec.duration_s = 3600.0 + 2400.0;
  spec.fault_s = 3600.0;
  spec.seed = 23;
  const mc::CaseResult r = mc::RunCase(spec, SensorModelDir());
  for (std::size_t i = 0; i < r.nodes.size(); ++i) {
    EXPECT_GE(r.dist_coverage[i], 0.9)
        << r.nodes[i] << " max error " << r.dist_max_error_K[i] << " K";
    EXPECT_LE(r.dist_max_error_K[i], 3.0) << r.nodes[i];
  }
}

TEST(DisturbanceSensor, AReadingThatStepsIsTakenAsAStepOfTheSensorsOffset) {
  // The reading jumps +3 K between two readings: the frame cannot move that fast, so the offset
  // takes the step and every node stays on the truth.
  ExpectEveryNodeCoveredWithin(RunSensorFault(mc::Fault::kSensorOffset, 24), 1.5);
}

TEST(DisturbanceSensor, ASmallerStepIsFoundToo) {
  // 1.2 K, above the offset alarm's 1 K: the test's noise is the reading's white noise (two
  // consecutive readings), not the larger sd the filter gives a reading for its correlated
  // quantisation error (with that, 0.12 K, this step is missed).
  mc::CaseSpec spec;
  spec.fault = mc::Fault::kSensorOffset;
  spec.sensor_offset_K = 1.2;
  spec.duration_s = 3600.0 + 2400.0;
  spec.fault_s = 3600.0;
  spec.seed = 28;
  const mc::CaseResult r = mc::RunCase(spec, SensorModelDir());
  EXPECT_EQ(r.dist_sensor_steps, 1);
  ExpectEveryNodeCoveredWithin(r, 1.5);
}

TEST(DisturbanceSensor, WithoutTheStepTestTheFrameFollowsTheSteppedReading) {
  // The same run with the step test off: the lag state turns the step into a frame temperature
  // step, and the frame estimate is confidently wrong (what the test above guards against).
  pe::DisturbanceSensorConfig dc;
  dc.sensor_step_gate_sd = 0.0;
  const mc::CaseResult r = RunSensorFault(mc::Fault::kSensorOffset, 24, 0.0, 0.0, dc);
  const std::size_t frame = NodeIndex(r, "frame");
  ASSERT_LT(frame, r.nodes.size());
  EXPECT_GT(r.dist_max_error_K[frame], 5.0);
  EXPECT_LT(r.dist_coverage[frame], 0.9);
}

TEST(DisturbanceSensor, HealthyAndLostCoolingRunsFindNoSensorStep) {
  // The step test must not take a plant change for the sensor: lost cooling moves the frame fast,
  // but no faster than the frame-path heat's random walk allows.
  for (const mc::Fault f : {mc::Fault::kNone, mc::Fault::kCoolingLost, mc::Fault::kAmbientRise}) {
    const mc::CaseResult r = RunSensorFault(f, 25);
    EXPECT_EQ(r.dist_sensor_steps, 0) << mc::FaultName(f);
  }
}

}  // namespace
