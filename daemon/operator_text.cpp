#include "daemon/operator_text.hpp"

#include <fmt/format.h>

#include <algorithm>
#include <cmath>
#include <ctime>

namespace pumptherm::daemon {
namespace {

/// The mismatch test's largest frame-to-ambient resistance scale (its fit's bound,
/// estimators/mismatch_detector.cpp): a fit there says only that the cooling is (nearly) gone.
constexpr double kResistanceScaleCap = 20.0;

}  // namespace

std::string LocalTimeText(std::int64_t unix_us, bool with_ms) {
  // Whole seconds rounded down (a time before 1970 too), the remainder in [0, 1 s).
  const std::int64_t s = unix_us >= 0 ? unix_us / 1'000'000 : -((999'999 - unix_us) / 1'000'000);
  const auto t = static_cast<std::time_t>(s);
  std::tm tm{};
  localtime_r(&t, &tm);
  char date[32];
  char zone[16];
  std::strftime(date, sizeof date, "%Y-%m-%d %H:%M:%S", &tm);
  std::strftime(zone, sizeof zone, "%Z", &tm);
  if (!with_ms) return fmt::format("{} {}", date, zone);
  return fmt::format("{}.{:03} {}", date, (unix_us - s * 1'000'000) / 1000, zone);
}

std::string DurationText(double s) {
  if (!std::isfinite(s)) return "never";
  const long total = std::lround(std::max(s, 0.0));
  if (total < 60) return fmt::format("{} s", total);
  if (total < 3600) {
    return total % 60 == 0 ? fmt::format("{} min", total / 60)
                           : fmt::format("{} min {:02} s", total / 60, total % 60);
  }
  const long minutes = (total % 3600) / 60;
  return minutes == 0 ? fmt::format("{} h", total / 3600)
                      : fmt::format("{} h {:02} min", total / 3600, minutes);
}

std::string ReasonWords(estimators::AlarmReason reason) {
  std::string s = estimators::AlarmReasonName(reason);
  std::replace(s.begin(), s.end(), '_', ' ');
  return s;
}

std::string AlarmNodeName(int node, const std::vector<std::string>& node_names) {
  if (node < 0) return "";
  const auto i = static_cast<std::size_t>(node);
  if (i < node_names.size()) return node_names[i];
  return i == node_names.size() ? "winding_resistance" : "";
}

std::string NodeWords(std::string_view alarm_node_name) {
  return alarm_node_name == "winding_resistance" ? "winding from resistance"
                                                 : std::string(alarm_node_name);
}

bool DiagnosisBlames(estimators::MismatchState state) {
  using S = estimators::MismatchState;
  return state == S::kPlantChange || state == S::kSensorFaultSuspected || state == S::kUnexplained;
}

std::string CauseText(estimators::MismatchState state, estimators::MismatchEffect effect, double v,
                      std::string_view measured_node) {
  using E = estimators::MismatchEffect;
  if (!DiagnosisBlames(state)) return "";
  switch (effect) {
    case E::kFrameAmbientResistance:
      return fmt::format("{} (frame-to-ambient resistance x{:.3g}{})",
                         v >= 2.0  ? "cooling lost"
                         : v > 1.0 ? "cooling reduced"
                                   : "cooling better than modelled",
                         v, v >= kResistanceScaleCap ? " or more" : "");
    case E::kRotorLoss:
      return fmt::format("heat inside the rotor ({:+.0f} W: bearing, gas friction)", v);
    case E::kLossScale:
      return fmt::format("{} heat than modelled (losses x{:.2f})", v >= 1.0 ? "more" : "less", v);
    case E::kUnmeasuredAmbient:
      return fmt::format("surroundings {} than the ambient sensor reads ({:+.1f} K)",
                         v >= 0.0 ? "warmer" : "cooler", v);
    case E::kSensorOffset:
      return fmt::format("{} sensor reads {:+.1f} K off (the sensor, not the plant)", measured_node,
                         v);
    case E::kSensorStuck:
      return fmt::format("{} sensor stuck at {:.1f} degC (the sensor, not the plant)",
                         measured_node, v);
    case E::kSensorLag:
      return fmt::format(
          "{} sensor lags about {:.0f} s, not as configured (its frame_sensor_lag_s; the sensor, "
          "not the plant)",
          measured_node, v);
    case E::kNone:
      break;
  }
  return fmt::format("the model no longer explains the {} sensor, cause not named yet",
                     measured_node);
}

}  // namespace pumptherm::daemon
