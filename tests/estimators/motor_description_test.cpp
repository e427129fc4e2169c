#include <gtest/gtest.h>

#include <cmath>
#include <cstdlib>
#include <fstream>
#include <numbers>
#include <sstream>
#include <string>

#include "estimators/magnet.hpp"
#include "estimators/motor.hpp"
#include "tests/common/test_files.hpp"

namespace pumptherm::estimators {
namespace {

// Parses `text` and returns the error message, or "" when it parsed.
std::string ErrorOf(const std::string& text) {
  try {
    ParseMotorDescription(text, "m.toml");
  } catch (const MotorDescriptionError& e) {
    return e.what();
  }
  return "";
}

constexpr const char* kValid = R"(name = "test"
pole_pairs = 2
rated_speed_rpm = 3000
flux_Wb = 0.1
inductance_H = 1e-3
[resistance]
r0_ohm = 0.5
t0_degC = 20.0
alpha_per_K = 3.93e-3
)";

// Han, Xiong, Mao 2019, Table 1, and section 3.1 for alpha.
TEST(MotorDescription, PresetHasTable1Values) {
  const MotorDescription m = MotorPreset("han2019-tmp");
  EXPECT_EQ(m.name, "han2019-tmp");
  EXPECT_EQ(m.pole_pairs, 1);
  EXPECT_DOUBLE_EQ(m.rated_speed_rpm, 21000.0);
  EXPECT_DOUBLE_EQ(m.flux_Wb, 0.0182);
  EXPECT_DOUBLE_EQ(m.inductance_H, 0.24e-3);
  EXPECT_DOUBLE_EQ(m.copper.r0_ohm, 0.28);
  EXPECT_DOUBLE_EQ(m.copper.alpha_per_K, 4.1e-3);
  EXPECT_DOUBLE_EQ(m.copper.t0_degC, 27.2);
  EXPECT_EQ(MotorPresetNames(), std::vector<std::string>{"han2019-tmp"});
}

TEST(MotorDescription, ShippedPresetFileMatchesBuiltInPreset) {
  const std::string text = pumptherm::test_files::ReadFile(pumptherm::test_files::SourceDir() +
                                                           "/estimators/motors/han2019-tmp.toml");
  EXPECT_EQ(text, std::string(MotorPresetText("han2019-tmp")));
}

TEST(MotorDescription, ParsesAValidFileWithIntegersForFloats) {
  const MotorDescription m = ParseMotorDescription(kValid, "m.toml");
  EXPECT_EQ(m.pole_pairs, 2);
  EXPECT_DOUBLE_EQ(m.rated_speed_rpm, 3000.0);
  EXPECT_DOUBLE_EQ(m.plausible_min_degC, -20.0);  // defaults
  EXPECT_DOUBLE_EQ(m.plausible_max_degC, 180.0);
  // 3000 r/min with 2 pole pairs: 2 * 3000 * 2 pi / 60 = 628.3 rad/s.
  EXPECT_NEAR(ElectricalSpeed_rad_per_s(m, 3000.0), 200.0 * std::numbers::pi, 1e-12);
  EXPECT_NEAR(PlausibleMaxResistance_ohm(m), 0.5 * (1.0 + 3.93e-3 * 160.0), 1e-12);
}

TEST(MotorDescription, MissingKeyNamesLineAndKey) {
  std::string text = kValid;
  text.replace(text.find("flux_Wb = 0.1\n"), 14, "");
  const std::string err = ErrorOf(text);
  EXPECT_NE(err.find("m.toml:1"), std::string::npos) << err;
  EXPECT_NE(err.find("'flux_Wb'"), std::string::npos) << err;
  std::string no_r0 = kValid;
  no_r0.replace(no_r0.find("r0_ohm = 0.5\n"), 13, "");
  const std::string err2 = ErrorOf(no_r0);
  EXPECT_NE(err2.find("m.toml:6"), std::string::npos) << err2;  // the [resistance] table
  EXPECT_NE(err2.find("'resistance.r0_ohm'"), std::string::npos) << err2;
}

TEST(MotorDescription, UnknownKeyNamesLineAndKey) {
  const std::string err = ErrorOf(std::string(kValid) + "alpha_per_k = 1.0\n");
  EXPECT_NE(err.find("m.toml:10"), std::string::npos) << err;
  EXPECT_NE(err.find("'resistance.alpha_per_k'"), std::string::npos) << err;
}

TEST(MotorDescription, WrongTypeNamesLineAndKey) {
  std::string text = kValid;
  text.replace(text.find("inductance_H = 1e-3"), 19, "inductance_H = \"1 mH\"");
  const std::string err = ErrorOf(text);
  EXPECT_NE(err.find("m.toml:5"), std::string::npos) << err;
  EXPECT_NE(err.find("'inductance_H' must be a number"), std::string::npos) << err;
}

TEST(MotorDescription, OutOfRangeValuesAreErrors) {
  std::string pp = kValid;
  pp.replace(pp.find("pole_pairs = 2"), 14, "pole_pairs = 0");
  EXPECT_NE(ErrorOf(pp).find("m.toml:2: key 'pole_pairs'"), std::string::npos) << ErrorOf(pp);
  std::string neg = kValid;
  neg.replace(neg.find("r0_ohm = 0.5"), 12, "r0_ohm = -0.5");
  EXPECT_NE(ErrorOf(neg).find("m.toml:7: key 'resistance.r0_ohm' must be positive"),
            std::string::npos)
      << ErrorOf(neg);
  const std::string band =
      std::string(kValid) + "plausible_min_degC = 100.0\nplausible_max_degC = 50.0\n";
  EXPECT_NE(ErrorOf(band).find("plausible_min_degC"), std::string::npos) << ErrorOf(band);
  // Found by motor_description_fuzz: alpha_per_K = 4.1e-31 was accepted, an empty resistance band.
  std::string alpha = kValid;
  alpha.replace(alpha.find("alpha_per_K = 3.93e-3"), 21, "alpha_per_K = 4.1e-31");
  EXPECT_NE(ErrorOf(alpha).find("key 'resistance.alpha_per_K' must be within [0.0001, 0.02]"),
            std::string::npos)
      << ErrorOf(alpha);
  // A band too narrow to tell two resistances apart.
  const std::string thin =
      std::string(kValid) + "plausible_min_degC = 1.0\nplausible_max_degC = 1.0000000000000002\n";
  EXPECT_NE(ErrorOf(thin).find("plausible_min_degC"), std::string::npos) << ErrorOf(thin);
}

// The optional [drive] table: the step of the reported uq (the identifier's quantisation-bias
// correction); absent, no correction (0).
TEST(MotorDescription, DriveTableGivesTheUqResolution) {
  EXPECT_EQ(ParseMotorDescription(kValid, "m.toml").uq_resolution_V, 0.0);
  EXPECT_EQ(MotorPreset("han2019-tmp").uq_resolution_V, 0.0);
  const MotorDescription m = ParseMotorDescription(
      std::string(kValid) + "[drive]\nuq_resolution_V = 0.0234375\n", "m.toml");
  EXPECT_DOUBLE_EQ(m.uq_resolution_V, 96.0 / 4096.0);
  EXPECT_EQ(ParseMotorDescription(std::string(kValid) + "[drive]\n", "m.toml").uq_resolution_V,
            0.0);
  const std::string zero = ErrorOf(std::string(kValid) + "[drive]\nuq_resolution_V = 0\n");
  EXPECT_NE(zero.find("m.toml:11: key 'drive.uq_resolution_V' must be within (0, 10] V, got 0"),
            std::string::npos)
      << zero;
  const std::string huge = ErrorOf(std::string(kValid) + "[drive]\nuq_resolution_V = 48\n");
  EXPECT_NE(huge.find("'drive.uq_resolution_V' must be within (0, 10] V"), std::string::npos)
      << huge;
  const std::string text = ErrorOf(std::string(kValid) + "[drive]\nuq_resolution_V = \"23 mV\"\n");
  EXPECT_NE(text.find("m.toml:11: key 'drive.uq_resolution_V' must be a number"), std::string::npos)
      << text;
  const std::string unknown = ErrorOf(std::string(kValid) + "[drive]\nud_resolution_V = 0.02\n");
  EXPECT_NE(unknown.find("m.toml:11: unknown key 'drive.ud_resolution_V'"), std::string::npos)
      << unknown;
  const std::string not_table = ErrorOf(std::string("drive = 1.0\n") + kValid);
  EXPECT_NE(not_table.find("m.toml:1: key 'drive' must be a table"), std::string::npos)
      << not_table;
}

// The drive's current limit: what a telemetry silence may hide (estimators/alarm_bounds.hpp).
TEST(MotorDescription, DriveTableGivesTheLargestCurrent) {
  EXPECT_EQ(ParseMotorDescription(kValid, "m.toml").max_current_A, 0.0);  // not known
  EXPECT_DOUBLE_EQ(MotorPreset("han2019-tmp").max_current_A, 15.0);
  const MotorDescription m =
      ParseMotorDescription(std::string(kValid) + "[drive]\nmax_current_A = 40\n", "m.toml");
  EXPECT_DOUBLE_EQ(m.max_current_A, 40.0);
  for (const char* bad : {"0", "-3.0", "15000.0"}) {
    const std::string e = ErrorOf(std::string(kValid) + "[drive]\nmax_current_A = " + bad + "\n");
    EXPECT_NE(e.find("m.toml:11: key 'drive.max_current_A' must be within (0, 10000] A"),
              std::string::npos)
        << bad << ": " << e;
  }
  const std::string text = ErrorOf(std::string(kValid) + "[drive]\nmax_current_A = \"15 A\"\n");
  EXPECT_NE(text.find("m.toml:11: key 'drive.max_current_A' must be a number"), std::string::npos)
      << text;
  const std::string inf = ErrorOf(std::string(kValid) + "[drive]\nmax_current_A = inf\n");
  EXPECT_NE(inf.find("m.toml:11: key 'drive.max_current_A' is not a finite number"),
            std::string::npos)
      << inf;
}

// The optional [magnet] table and the temperature it gives from a flux (estimators/magnet.hpp):
// T = T0 + (psi/psi0 - 1)/beta, sd = sd_psi/(psi0 |beta|), worked by hand below.
TEST(MotorDescription, MagnetTableGivesTheFluxTemperatureLaw) {
  const MotorDescription none = ParseMotorDescription(kValid, "m.toml");
  EXPECT_FALSE(none.magnet.Given());
  EXPECT_TRUE(std::isnan(MagnetTemperatureFromFlux(none, 0.1, 1e-4).degC));
  const MotorDescription m = ParseMotorDescription(
      std::string(kValid) +
          "[magnet]\nt0_degC = 20.0\nflux_temperature_coefficient_per_K = -1.0e-3\n",
      "m.toml");
  ASSERT_TRUE(m.magnet.Given());
  // 0.1 Wb at 20 degC; 0.0995 Wb is 0.5 % less: 5 K hotter. sd 1e-5 Wb is 0.01 %: 0.1 K.
  const MagnetTemperature t = MagnetTemperatureFromFlux(m, 0.0995, 1e-5);
  EXPECT_NEAR(t.degC, 25.0, 1e-9);
  EXPECT_NEAR(t.sd_K, 0.1, 1e-12);
  EXPECT_NEAR(FluxAt_Wb(m, 25.0), 0.0995, 1e-15);
  EXPECT_TRUE(std::isnan(MagnetTemperatureFromFlux(m, std::nan(""), 1e-5).degC));
  // The preset: NdFeB assumed, psi_f at R0's temperature.
  const MotorDescription han = MotorPreset("han2019-tmp");
  EXPECT_DOUBLE_EQ(han.magnet.t0_degC, 27.2);
  EXPECT_DOUBLE_EQ(han.magnet.flux_temperature_coefficient_per_K, -1e-3);
  const std::string rising =
      ErrorOf(std::string(kValid) +
              "[magnet]\nt0_degC = 20.0\nflux_temperature_coefficient_per_K = 1e-3\n");
  EXPECT_NE(
      rising.find("m.toml:12: key 'magnet.flux_temperature_coefficient_per_K' must be within"),
      std::string::npos)
      << rising;
  const std::string missing =
      ErrorOf(std::string(kValid) + "[magnet]\nflux_temperature_coefficient_per_K = -1e-3\n");
  EXPECT_NE(missing.find("missing key 'magnet.t0_degC'"), std::string::npos) << missing;
  const std::string unknown = ErrorOf(std::string(kValid) + "[magnet]\ngrade = 1\n");
  EXPECT_NE(unknown.find("m.toml:11: unknown key 'magnet.grade'"), std::string::npos) << unknown;
}

// The optional inverter voltage error in [drive]: u_err and its knee; the q-axis share is
// u_err tanh(|i| / knee) iq / |i| (iq / |i| alone with knee 0).
TEST(MotorDescription, DriveTableGivesTheVoltageError) {
  EXPECT_EQ(ParseMotorDescription(kValid, "m.toml").voltage_error_V, 0.0);
  const MotorDescription m = ParseMotorDescription(
      std::string(kValid) + "[drive]\nvoltage_error_V = 0.15\nvoltage_error_knee_A = 0.5\n",
      "m.toml");
  EXPECT_DOUBLE_EQ(m.voltage_error_V, 0.15);
  EXPECT_DOUBLE_EQ(m.voltage_error_knee_A, 0.5);
  EXPECT_NEAR(VoltageErrorQ_V(m, 0.0, 2.0), 0.15 * std::tanh(4.0), 1e-15);
  EXPECT_NEAR(VoltageErrorQ_V(m, 0.0, -2.0), -0.15 * std::tanh(4.0), 1e-15);
  EXPECT_NEAR(VoltageErrorQ_V(m, 3.0, 4.0), 0.15 * std::tanh(10.0) * 0.8, 1e-15);
  EXPECT_EQ(VoltageErrorQ_V(m, 0.0, 0.0), 0.0);
  const MotorDescription sign =
      ParseMotorDescription(std::string(kValid) + "[drive]\nvoltage_error_V = 0.1\n", "m.toml");
  EXPECT_EQ(sign.voltage_error_knee_A, 0.0);
  EXPECT_DOUBLE_EQ(VoltageErrorQ_V(sign, 0.0, 0.01), 0.1);
  const std::string neg = ErrorOf(std::string(kValid) + "[drive]\nvoltage_error_V = -0.1\n");
  EXPECT_NE(neg.find("m.toml:11: key 'drive.voltage_error_V' must be within [0, 5] V, got -0.1"),
            std::string::npos)
      << neg;
  const std::string knee_alone =
      ErrorOf(std::string(kValid) + "[drive]\nvoltage_error_knee_A = 0.5\n");
  EXPECT_NE(
      knee_alone.find("m.toml:11: key 'drive.voltage_error_knee_A' needs 'drive.voltage_error_V'"),
      std::string::npos)
      << knee_alone;
  const std::string bad_knee =
      ErrorOf(std::string(kValid) + "[drive]\nvoltage_error_V = 0.1\nvoltage_error_knee_A = -1\n");
  EXPECT_NE(bad_knee.find("m.toml:12: key 'drive.voltage_error_knee_A' must be within [0, 100] A"),
            std::string::npos)
      << bad_knee;
}

TEST(MotorDescription, SyntaxErrorNamesLine) {
  const std::string err = ErrorOf("pole_pairs = 1\nflux_Wb = = 3\n");
  EXPECT_NE(err.find("m.toml:2:"), std::string::npos) << err;
}

TEST(MotorDescription, UnknownPresetThrows) {
  EXPECT_THROW(MotorPreset("no-such-motor"), MotorDescriptionError);
  EXPECT_TRUE(MotorPresetText("no-such-motor").empty());
}

}  // namespace
}  // namespace pumptherm::estimators
