#pragma once
/// Sample messages of every pumptherm LCM type and field-by-field comparisons, shared by
/// lcm_types_test.cpp (encode/decode) and lcm_memq_test.cpp (publish/subscribe).
/// The samples exercise the awkward values: NaN (not measured), +/-Inf, -0.0, extreme
/// integers, empty and non-ASCII strings, empty and non-empty arrays, nested types.

#include <gtest/gtest.h>

#include <cstdint>
#include <cstring>
#include <limits>
#include <pumptherm/alarm_clear_reply_t.hpp>
#include <pumptherm/alarm_clear_t.hpp>
#include <pumptherm/alarm_t.hpp>
#include <pumptherm/gateway_health_t.hpp>
#include <pumptherm/telemetry_t.hpp>
#include <pumptherm/temperatures_t.hpp>
#include <string>
#include <vector>

namespace pumptherm::test {

inline constexpr double kNaN = std::numeric_limits<double>::quiet_NaN();
inline constexpr double kInf = std::numeric_limits<double>::infinity();

/// Bitwise equality of doubles: NaN equals NaN, -0.0 differs from 0.0.
inline ::testing::AssertionResult SameBits(double expected, double actual) {
  std::uint64_t a = 0;
  std::uint64_t b = 0;
  std::memcpy(&a, &expected, sizeof a);
  std::memcpy(&b, &actual, sizeof b);
  if (a == b) {
    return ::testing::AssertionSuccess();
  }
  return ::testing::AssertionFailure() << "expected " << expected << " (bits " << std::hex << a
                                       << "), got " << actual << " (bits " << b << ")";
}

inline telemetry_t SampleTelemetry() {
  telemetry_t m;
  m.utime = 1'763'776'800'123'456;
  m.pump = "tmp-07";
  m.node_id = 0x1F;
  m.id_A = -0.0;
  m.iq_A = 2.345678901234567;
  m.ud_V = -0.793;
  m.uq_V = 40.125;
  m.speed_rpm = 21000.5;
  m.rolling_counter = std::numeric_limits<std::int16_t>::min();
  m.drive_state = telemetry_t::DRIVE_STATE_BRAKING;
  m.frame_sensor_degC = 41.3;
  m.ambient_degC = 22.0;
  m.coolant_degC = kNaN;
  m.dc_link_V = 47.9;
  m.status_age_s = 0.1;
  return m;
}

inline void ExpectSame(const telemetry_t& e, const telemetry_t& a) {
  EXPECT_EQ(e.utime, a.utime);
  EXPECT_EQ(e.pump, a.pump);
  EXPECT_EQ(e.node_id, a.node_id);
  EXPECT_TRUE(SameBits(e.id_A, a.id_A));
  EXPECT_TRUE(SameBits(e.iq_A, a.iq_A));
  EXPECT_TRUE(SameBits(e.ud_V, a.ud_V));
  EXPECT_TRUE(SameBits(e.uq_V, a.uq_V));
  EXPECT_TRUE(SameBits(e.speed_rpm, a.speed_rpm));
  EXPECT_EQ(e.rolling_counter, a.rolling_counter);
  EXPECT_EQ(e.drive_state, a.drive_state);
  EXPECT_TRUE(SameBits(e.frame_sensor_degC, a.frame_sensor_degC));
  EXPECT_TRUE(SameBits(e.ambient_degC, a.ambient_degC));
  EXPECT_TRUE(SameBits(e.coolant_degC, a.coolant_degC));
  EXPECT_TRUE(SameBits(e.dc_link_V, a.dc_link_V));
  EXPECT_TRUE(SameBits(e.status_age_s, a.status_age_s));
}

/// `nodes`: thermal-network node names (the Saheba 2010 seven by default; may be empty).
inline temperatures_t SampleTemperatures(std::vector<std::string> nodes = {
                                             "frame", "yoke", "teeth", "slot_winding",
                                             "end_winding", "rotor", "shaft"}) {
  temperatures_t m;
  m.utime = 1'763'776'801'000'000;
  m.pump = "tmp-07";
  m.resistance_ohm = 0.3012;
  m.resistance_sd_ohm = 0.0021;
  m.flux_Wb = 0.01815;
  m.flux_sd_Wb = 4.0e-5;
  m.winding_resistance_degC = 61.25;
  m.winding_resistance_sd_K = 1.4;
  m.magnet_flux_degC = 48.5;
  m.magnet_flux_sd_K = 2.2;
  m.ident_status = temperatures_t::IDENT_NOT_IDENTIFIABLE;
  m.num_nodes = static_cast<std::int32_t>(nodes.size());
  for (std::size_t i = 0; i < nodes.size(); ++i) {
    m.node_names.push_back(nodes[i]);
    m.node_degC.push_back(i == 0 ? kNaN : 30.0 + 3.5 * static_cast<double>(i));
    m.node_sd_K.push_back(i == 1 ? kInf : 0.25 * static_cast<double>(i + 1));
  }
  m.nis = 3.9;
  m.filter_status = temperatures_t::FILTER_REJECTING;
  return m;
}

inline void ExpectSame(const temperatures_t& e, const temperatures_t& a) {
  EXPECT_EQ(e.utime, a.utime);
  EXPECT_EQ(e.pump, a.pump);
  EXPECT_TRUE(SameBits(e.resistance_ohm, a.resistance_ohm));
  EXPECT_TRUE(SameBits(e.resistance_sd_ohm, a.resistance_sd_ohm));
  EXPECT_TRUE(SameBits(e.flux_Wb, a.flux_Wb));
  EXPECT_TRUE(SameBits(e.flux_sd_Wb, a.flux_sd_Wb));
  EXPECT_TRUE(SameBits(e.winding_resistance_degC, a.winding_resistance_degC));
  EXPECT_TRUE(SameBits(e.winding_resistance_sd_K, a.winding_resistance_sd_K));
  EXPECT_TRUE(SameBits(e.magnet_flux_degC, a.magnet_flux_degC));
  EXPECT_TRUE(SameBits(e.magnet_flux_sd_K, a.magnet_flux_sd_K));
  EXPECT_EQ(e.ident_status, a.ident_status);
  ASSERT_EQ(e.num_nodes, a.num_nodes);
  ASSERT_EQ(e.node_names, a.node_names);
  ASSERT_EQ(a.node_degC.size(), static_cast<std::size_t>(a.num_nodes));
  ASSERT_EQ(a.node_sd_K.size(), static_cast<std::size_t>(a.num_nodes));
  for (std::size_t i = 0; i < e.node_degC.size(); ++i) {
    EXPECT_TRUE(SameBits(e.node_degC[i], a.node_degC[i])) << "node " << e.node_names[i];
    EXPECT_TRUE(SameBits(e.node_sd_K[i], a.node_sd_K[i])) << "node " << e.node_names[i];
  }
  EXPECT_TRUE(SameBits(e.nis, a.nis));
  EXPECT_EQ(e.filter_status, a.filter_status);
}

/// `conditions`: how many active conditions the sample carries (0 is a normal pump).
inline alarm_t SampleAlarm(int conditions = 2) {
  alarm_t m;
  m.utime = 1'763'776'802'000'000;
  m.pump = "tmp-07";
  m.level = conditions > 0 ? alarm_t::LEVEL_TRIP : alarm_t::LEVEL_NORMAL;
  m.time_to_trip_s = conditions > 0 ? 0.0 : kInf;
  m.forecast_node = conditions > 0 ? "end_winding" : "";
  for (int i = 0; i < conditions; ++i) {
    alarm_condition_t c;
    c.level = i == 0 ? alarm_t::LEVEL_TRIP : alarm_t::LEVEL_WARNING;
    c.reason = i == 0 ? alarm_condition_t::REASON_ESTIMATED_OVER_TEMPERATURE
                      : alarm_condition_t::REASON_STALE_TELEMETRY;
    c.node = i == 0 ? "end_winding" : "telemetry";
    c.value_degC = i == 0 ? 131.7 : kNaN;
    c.threshold_degC = i == 0 ? 130.0 : kNaN;
    c.rate_K_per_s = i == 0 ? 0.012 : -kInf;
    c.since_utime = m.utime - 1'000'000 * (i + 1);
    c.latched = i == 0;
    m.conditions.push_back(c);
  }
  m.num_conditions = conditions;
  m.mismatch_state = conditions > 0 ? 2 : 0;
  m.mismatch_effect = conditions > 0 ? 1 : 0;
  m.mismatch_value = conditions > 0 ? 3.8 : std::numeric_limits<double>::quiet_NaN();
  m.mismatch_since_utime = conditions > 0 ? m.utime - 600'000'000 : 0;
  return m;
}

inline void ExpectSame(const alarm_t& e, const alarm_t& a) {
  EXPECT_EQ(e.utime, a.utime);
  EXPECT_EQ(e.pump, a.pump);
  EXPECT_EQ(e.level, a.level);
  EXPECT_TRUE(SameBits(e.time_to_trip_s, a.time_to_trip_s));
  EXPECT_EQ(e.forecast_node, a.forecast_node);
  ASSERT_EQ(e.num_conditions, a.num_conditions);
  ASSERT_EQ(a.conditions.size(), static_cast<std::size_t>(a.num_conditions));
  for (std::size_t i = 0; i < e.conditions.size(); ++i) {
    SCOPED_TRACE("condition " + std::to_string(i));
    const alarm_condition_t& ec = e.conditions[i];
    const alarm_condition_t& ac = a.conditions[i];
    EXPECT_EQ(ec.level, ac.level);
    EXPECT_EQ(ec.reason, ac.reason);
    EXPECT_EQ(ec.node, ac.node);
    EXPECT_TRUE(SameBits(ec.value_degC, ac.value_degC));
    EXPECT_TRUE(SameBits(ec.threshold_degC, ac.threshold_degC));
    EXPECT_TRUE(SameBits(ec.rate_K_per_s, ac.rate_K_per_s));
    EXPECT_EQ(ec.since_utime, ac.since_utime);
    EXPECT_EQ(ec.latched, ac.latched);
  }
  EXPECT_EQ(e.mismatch_state, a.mismatch_state);
  EXPECT_EQ(e.mismatch_effect, a.mismatch_effect);
  EXPECT_TRUE(SameBits(e.mismatch_value, a.mismatch_value));
  EXPECT_EQ(e.mismatch_since_utime, a.mismatch_since_utime);
}

inline alarm_clear_t SampleAlarmClear() {
  alarm_clear_t m;
  m.utime = 1'763'776'803'000'000;
  m.gateway = "hall-2";
  m.pump = "tmp-07";
  m.node = "winding";
  m.key_id = "0123456789abcdef";
  m.comment = "Wicklung geprüft, Störung behoben";  // non-ASCII UTF-8 on purpose
  m.counter = 1'763'776'803'000'017;
  // Bytes above 127 on purpose (Java's byte is signed).
  for (int i = 0; i < 32; ++i) m.tag[i] = static_cast<std::uint8_t>(i * 8 + 3);
  for (int i = 0; i < 64; ++i) m.signature[i] = static_cast<std::uint8_t>(i * 4 + 1);
  return m;
}

inline void ExpectSame(const alarm_clear_t& e, const alarm_clear_t& a) {
  EXPECT_EQ(e.utime, a.utime);
  EXPECT_EQ(e.gateway, a.gateway);
  EXPECT_EQ(e.pump, a.pump);
  EXPECT_EQ(e.node, a.node);
  EXPECT_EQ(e.key_id, a.key_id);
  EXPECT_EQ(e.comment, a.comment);
  EXPECT_EQ(e.counter, a.counter);
  for (int i = 0; i < 32; ++i) EXPECT_EQ(e.tag[i], a.tag[i]) << "tag[" << i << "]";
  for (int i = 0; i < 64; ++i)
    EXPECT_EQ(e.signature[i], a.signature[i]) << "signature[" << i << "]";
}

inline alarm_clear_reply_t SampleAlarmClearReply() {
  alarm_clear_reply_t m;
  m.utime = 1'763'776'803'250'000;
  m.gateway = "hall-2";
  m.pump = "tmp-07";
  m.key_id = "0123456789abcdef";
  m.counter = 1'763'776'803'000'017;
  m.result = alarm_clear_reply_t::RESULT_NODE_NOT_LATCHED;
  m.reason = "node 'frame' has no latched trip";
  m.last_counter = 1'763'776'803'000'016;
  m.trip_latched = true;
  for (int i = 0; i < 64; ++i) m.signature[i] = static_cast<std::uint8_t>(255 - i * 3);
  return m;
}

inline void ExpectSame(const alarm_clear_reply_t& e, const alarm_clear_reply_t& a) {
  EXPECT_EQ(e.utime, a.utime);
  EXPECT_EQ(e.gateway, a.gateway);
  EXPECT_EQ(e.pump, a.pump);
  EXPECT_EQ(e.key_id, a.key_id);
  EXPECT_EQ(e.counter, a.counter);
  EXPECT_EQ(e.result, a.result);
  EXPECT_EQ(e.reason, a.reason);
  EXPECT_EQ(e.last_counter, a.last_counter);
  EXPECT_EQ(e.trip_latched, a.trip_latched);
  for (int i = 0; i < 64; ++i)
    EXPECT_EQ(e.signature[i], a.signature[i]) << "signature[" << i << "]";
}

/// `interfaces`: how many CAN interfaces the sample reports.
inline gateway_health_t SampleGatewayHealth(int interfaces = 2) {
  gateway_health_t m;
  m.utime = 1'763'776'804'000'000;
  m.uptime_s = 86'400.25;
  m.num_pumps = 32;
  m.lcm_publish_failures = std::numeric_limits<std::int64_t>::max();
  m.clears_accepted = 3;
  m.clears_refused = 200'017;
  m.clears_unauthenticated = 200'001;
  m.mqtt_enabled = true;
  m.mqtt_connected = false;
  m.mqtt_dropped = 4'000'000'000;
  m.mqtt_alarms_dropped = 7;
  for (int i = 0; i < interfaces; ++i) {
    interface_health_t h;
    h.name = "can" + std::to_string(i);
    h.bus_state =
        i == 0 ? interface_health_t::BUS_STATE_ERROR_ACTIVE : interface_health_t::BUS_STATE_DOWN;
    h.rx_frames_per_s = 3520.0 - i;
    h.tx_frames_per_s = 320.0 + i;
    h.rx_frames = 304'128'000 + i;
    h.tx_frames = 27'648'000 + i;
    h.rx_dropped = 3 + i;
    h.tx_dropped = 1 + i;
    h.rx_rejected = 17 + i;
    h.error_frames = 5 + i;
    h.reopens = i;
    h.rx_second_sender = 40 + i;
    m.interfaces.push_back(h);
  }
  m.num_interfaces = interfaces;
  return m;
}

inline void ExpectSame(const gateway_health_t& e, const gateway_health_t& a) {
  EXPECT_EQ(e.utime, a.utime);
  EXPECT_TRUE(SameBits(e.uptime_s, a.uptime_s));
  EXPECT_EQ(e.num_pumps, a.num_pumps);
  EXPECT_EQ(e.lcm_publish_failures, a.lcm_publish_failures);
  EXPECT_EQ(e.clears_accepted, a.clears_accepted);
  EXPECT_EQ(e.clears_refused, a.clears_refused);
  EXPECT_EQ(e.clears_unauthenticated, a.clears_unauthenticated);
  EXPECT_EQ(e.mqtt_enabled, a.mqtt_enabled);
  EXPECT_EQ(e.mqtt_connected, a.mqtt_connected);
  EXPECT_EQ(e.mqtt_dropped, a.mqtt_dropped);
  EXPECT_EQ(e.mqtt_alarms_dropped, a.mqtt_alarms_dropped);
  ASSERT_EQ(e.num_interfaces, a.num_interfaces);
  ASSERT_EQ(a.interfaces.size(), static_cast<std::size_t>(a.num_interfaces));
  for (std::size_t i = 0; i < e.interfaces.size(); ++i) {
    SCOPED_TRACE("interface " + e.interfaces[i].name);
    const interface_health_t& eh = e.interfaces[i];
    const interface_health_t& ah = a.interfaces[i];
    EXPECT_EQ(eh.name, ah.name);
    EXPECT_EQ(eh.bus_state, ah.bus_state);
    EXPECT_TRUE(SameBits(eh.rx_frames_per_s, ah.rx_frames_per_s));
    EXPECT_TRUE(SameBits(eh.tx_frames_per_s, ah.tx_frames_per_s));
    EXPECT_EQ(eh.rx_frames, ah.rx_frames);
    EXPECT_EQ(eh.tx_frames, ah.tx_frames);
    EXPECT_EQ(eh.rx_dropped, ah.rx_dropped);
    EXPECT_EQ(eh.tx_dropped, ah.tx_dropped);
    EXPECT_EQ(eh.rx_rejected, ah.rx_rejected);
    EXPECT_EQ(eh.error_frames, ah.error_frames);
    EXPECT_EQ(eh.reopens, ah.reopens);
    EXPECT_EQ(eh.rx_second_sender, ah.rx_second_sender);
  }
}

}  // namespace pumptherm::test
