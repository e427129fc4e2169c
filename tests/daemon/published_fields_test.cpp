// The declaration of the published fields (daemon/published_fields.hpp): every row's default
// signal is in the shipped DBC, names and columns are unique, the shipped mapping binds every
// default, and one estimate reaches LCM and the CSV with the same values.
#include "daemon/published_fields.hpp"

#include <gtest/gtest.h>

#include <cmath>
#include <set>
#include <string>
#include <vector>

#include "daemon/resources.hpp"
#include "protocol/dbc.hpp"

namespace pumptherm::daemon {
namespace {

protocol::Dbc ShippedDbc() {
  const std::string path = ResolveResource(ResourceKind::kDbc, "pumptherm.dbc");
  return protocol::ParseDbc(ReadTextFile(path), path);
}

/// The cells of a CSV line, an empty last cell included ("a," is two cells).
std::vector<std::string> Split(const std::string& s) {
  std::vector<std::string> out;
  std::size_t from = 0;
  for (std::size_t comma = s.find(','); comma != std::string::npos; comma = s.find(',', from)) {
    out.push_back(s.substr(from, comma - from));
    from = comma + 1;
  }
  out.push_back(s.substr(from));
  return out;
}

TEST(PublishedFields, EveryDefaultSignalIsInTheShippedDbc) {
  const protocol::Dbc dbc = ShippedDbc();
  for (const PublishedField& f : PublishedFields()) {
    if (f.dbc_message.empty()) continue;
    const protocol::DbcMessage* m = dbc.FindMessage(std::string(f.dbc_message));
    ASSERT_NE(m, nullptr) << f.name << ": no message " << f.dbc_message;
    EXPECT_GE(m->FindSignal(std::string(f.dbc_signal)), 0)
        << f.name << ": no signal " << f.dbc_message << "." << f.dbc_signal;
  }
}

TEST(PublishedFields, NamesColumnsAndLcmFieldsAreEachUsedOnce) {
  std::set<std::string> names, columns, signals;
  std::vector<LcmField> members;
  for (const PublishedField& f : PublishedFields()) {
    EXPECT_TRUE(names.insert(std::string(f.name)).second) << f.name;
    if (!f.old_key.empty()) {
      EXPECT_TRUE(names.insert(std::string(f.old_key)).second) << f.old_key;
    }
    if (f.csv.kind != CsvFormat::Kind::kNone) {
      EXPECT_TRUE(columns.insert(std::string(f.csv_column)).second) << f.csv_column;
    }
    if (!f.dbc_message.empty()) {
      EXPECT_TRUE(
          signals.insert(std::string(f.dbc_message) + "." + std::string(f.dbc_signal)).second)
          << f.name;
    }
    if (!std::holds_alternative<std::monostate>(f.lcm)) {
      for (const LcmField& m : members) EXPECT_FALSE(m == f.lcm) << f.name << ": LCM field twice";
      members.push_back(f.lcm);
    }
    EXPECT_NE(f.value, nullptr) << f.name;
    if (f.csv.kind == CsvFormat::Kind::kWord) {
      EXPECT_NE(f.word, nullptr) << f.name;
    }
  }
}

TEST(PublishedFields, TheShippedMappingSendsEveryDefault) {
  const protocol::Dbc dbc = ShippedDbc();
  const std::string path = ResolveResource(ResourceKind::kDbc, "mapping_pumptherm.toml");
  const protocol::SignalMapping m =
      protocol::ParseMapping(ReadTextFile(path), path, dbc, MappingOutputs());
  for (const PublishedField& f : PublishedFields()) {
    if (f.dbc_message.empty()) continue;
    const protocol::SignalRef* ref = m.output(f.name);
    ASSERT_NE(ref, nullptr) << f.name;
    EXPECT_EQ(ref->message, f.dbc_message);
    EXPECT_EQ(ref->signal, f.dbc_signal);
  }
  EXPECT_TRUE(m.deprecations.empty());
}

// The identifier's status is `ident_status` everywhere (CSV, LCM, mapping key, MQTT metric); a
// mapping written with its old key `rs_status` still sends it, with a deprecation line.
TEST(PublishedFields, TheIdentifiersStatusIsIdentStatusAndItsOldKeyStillReads) {
  const PublishedField* f = FindPublishedField("ident_status");
  ASSERT_NE(f, nullptr);
  EXPECT_EQ(f->csv_column, "ident_status");
  EXPECT_EQ(FindPublishedField("rs_status"), nullptr);
  const protocol::SignalMapping m = protocol::ParseMapping(
      "[inputs]\n"
      "id_A = { message = \"PUMP_FAST_I\", signal = \"Id_A\" }\n"
      "iq_A = { message = \"PUMP_FAST_I\", signal = \"Iq_A\" }\n"
      "ud_V = { message = \"PUMP_FAST_U\", signal = \"Ud_V\" }\n"
      "uq_V = { message = \"PUMP_FAST_U\", signal = \"Uq_V\" }\n"
      "speed_mech_rpm = { message = \"PUMP_STATUS\", signal = \"SpeedMech_rpm\" }\n"
      "[outputs]\n"
      "defaults = false\n"
      "rs_status = { message = \"GW_IDENT\", signal = \"RsStatus\" }\n",
      "m.toml", ShippedDbc(), MappingOutputs());
  const protocol::SignalRef* ref = m.output("ident_status");
  ASSERT_NE(ref, nullptr);
  EXPECT_EQ(ref->signal, "RsStatus");
  ASSERT_EQ(m.deprecations.size(), 1u);
  EXPECT_EQ(m.deprecations[0],
            "m.toml:9:13: key outputs.rs_status is deprecated: it is now outputs.ident_status");
}

TEST(PublishedFields, OneEstimateReachesLcmAndTheCsvAlike) {
  estimators::PumpEstimate e;
  e.initialised = true;
  e.node_degC = {40.0, 50.0};
  e.node_sd_K = {1.0, 2.0};
  e.winding_resistance_degC = 81.25;
  e.winding_resistance_sd_K = 1.5;
  e.magnet_flux_degC = 61.5;
  e.magnet_flux_sd_K = 3.25;
  // The identification as published (the pump filter's), and the identifier's own beside it.
  e.identification.status = estimators::ResistanceStatus::kTracking;
  e.identification.resistance_ohm = 0.3125;
  e.resistance.status = estimators::ResistanceStatus::kHeld;
  e.resistance.resistance_ohm = 0.2875;
  e.alarm.level = estimators::AlarmLevel::kWarning;
  e.alarm.time_to_trip_s = std::numeric_limits<double>::infinity();
  e.mismatch.state = estimators::MismatchState::kPlantChange;
  e.mismatch.effect = estimators::MismatchEffect::kRotorLoss;
  e.mismatch.onset_s = 100.0;
  FieldSource s;
  s.estimate = &e;
  s.wall_offset_us = 1e12;
  pumptherm::temperatures_t t{};
  pumptherm::alarm_t a{};
  FillLcm(s, t);
  FillLcm(s, a);
  EXPECT_EQ(t.winding_resistance_degC, 81.25);
  EXPECT_EQ(t.winding_resistance_sd_K, 1.5);
  EXPECT_EQ(t.magnet_flux_sd_K, 3.25);
  EXPECT_EQ(t.resistance_ohm, 0.3125);
  EXPECT_EQ(t.ident_status, 2);
  EXPECT_EQ(a.level, 1);
  EXPECT_EQ(a.mismatch_state, 2);
  EXPECT_EQ(a.mismatch_effect, 2);
  EXPECT_EQ(a.mismatch_since_utime, 100'000'000 + 1'000'000'000'000);
  EXPECT_TRUE(std::isinf(a.time_to_trip_s));
  // The CSV: as many cells as columns, the same values.
  const std::vector<std::string> header = Split(CsvHeader().substr(1));
  std::string row;
  AppendCsvRow(s, row);
  const std::vector<std::string> cells = Split(row.substr(1));
  ASSERT_EQ(cells.size(), header.size());
  auto cell = [&](const std::string& column) {
    for (std::size_t i = 0; i < header.size(); ++i) {
      if (header[i] == column) return cells[i];
    }
    return std::string("(no column)");
  };
  EXPECT_EQ(cell("winding_resistance_degC"), "81.2500");
  EXPECT_EQ(cell("magnet_flux_sd_K"), "3.2500");
  // Codes as words (docs/daemon.md, "Names"); no time to trip: an empty cell.
  EXPECT_EQ(cell("alarm_level"), "warning");
  EXPECT_EQ(cell("ident_status"), "tracking");
  EXPECT_EQ(cell("identifier_status"), "held");
  EXPECT_EQ(cell("resistance_ohm"), "0.312500");
  EXPECT_EQ(cell("sensor_fault"), "none");
  EXPECT_EQ(cell("alarm_active_reasons"), "");
  EXPECT_EQ(cell("time_to_trip_s"), "");
  EXPECT_EQ(cell("mismatch_state"), "plant_change");
  EXPECT_EQ(cell("mismatch_effect"), "rotor_loss");
  EXPECT_EQ(cell("alarm_rule"), "");  // a warning without an over-temperature: no rule
  // The alarm's node by its name, every active reason joined by '+', a fault's kind as a word.
  e.alarm.level = estimators::AlarmLevel::kTrip;
  e.alarm.reason = estimators::AlarmReason::kEstimatedOverTemperature;
  e.alarm.node = -1;
  e.alarm.active_reasons = (1U << 4) | (1U << 8);
  e.alarm.time_to_trip_s = 276.2;
  e.sensor_fault = estimators::SensorFault::kOutOfRange;
  row.clear();
  AppendCsvRow(s, row);
  const std::vector<std::string> words = Split(row.substr(1));
  auto word = [&](const std::string& column) {
    for (std::size_t i = 0; i < header.size(); ++i) {
      if (header[i] == column) return words[i];
    }
    return std::string("(no column)");
  };
  EXPECT_EQ(word("alarm_level"), "trip");
  EXPECT_EQ(word("alarm_reason"), "estimated_over_temperature");
  EXPECT_EQ(word("alarm_node"), "winding_resistance");
  EXPECT_EQ(word("alarm_active_reasons"), "stale_telemetry+sensor_fault");
  EXPECT_EQ(word("sensor_fault"), "out_of_range");
  EXPECT_EQ(word("time_to_trip_s"), "276");
  EXPECT_EQ(word("alarm_rule"), "band");
  e.alarm_rule = estimators::AlarmRule::kSilence;
  row.clear();
  AppendCsvRow(s, row);
  const std::vector<std::string> again = Split(row.substr(1));
  ASSERT_EQ(again.size(), header.size());
  for (std::size_t i = 0; i < header.size(); ++i) {
    if (header[i] == "alarm_rule") {
      EXPECT_EQ(again[i], "silence");
    }
  }
  // Not available: NaN in LCM doubles and the CSV, -1 in LCM codes.
  estimators::PumpEstimate none;
  FieldSource n;
  n.estimate = &none;
  FillLcm(n, a);
  EXPECT_EQ(a.level, -1);
  FillLcm(n, t);
  EXPECT_TRUE(std::isnan(t.winding_resistance_degC));
}

}  // namespace
}  // namespace pumptherm::daemon
