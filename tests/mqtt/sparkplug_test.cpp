// The Sparkplug B payloads of the MQTT sink (daemon/mqtt_sparkplug.hpp), decoded with the
// schema (protocol/sparkplug_b.proto) and checked against the published fields and the rules of
// the Eclipse Sparkplug 3.0.0 specification (topics, seq, bdSeq, aliases, births and data).
#include <gtest/gtest.h>

#include <cmath>
#include <limits>
#include <map>
#include <set>
#include <string>
#include <vector>

#include "daemon/mqtt_sparkplug.hpp"
#include "protocol/mapping.hpp"
#include "protocol/sparkplug_b.pb.h"

namespace pumptherm::daemon::mqtt {
namespace {

namespace pb = org::eclipse::tahu::protobuf;
constexpr double kNaN = std::numeric_limits<double>::quiet_NaN();

pb::Payload Decode(const std::string& bytes) {
  pb::Payload p;
  EXPECT_TRUE(p.ParseFromString(bytes));
  return p;
}

estimators::PumpEstimate SomeEstimate() {
  estimators::PumpEstimate e;
  e.initialised = true;
  e.node_degC = {40.0, 50.0};
  e.node_sd_K = {1.0, 2.0};
  e.winding_resistance_degC = 81.25;
  e.winding_resistance_sd_K = 1.5;
  e.resistance.status = estimators::ResistanceStatus::kTracking;
  e.resistance.resistance_ohm = 0.3125;
  e.alarm.level = estimators::AlarmLevel::kWarning;
  e.alarm.time_to_trip_s = std::numeric_limits<double>::infinity();
  e.mismatch.state = estimators::MismatchState::kPlantChange;
  return e;
}

const std::vector<std::string> kNodes{"winding", "rotor"};

std::size_t IndexOf(const std::vector<MetricSpec>& metrics, const std::string& name) {
  for (std::size_t k = 0; k < metrics.size(); ++k)
    if (metrics[k].name == name) return k;
  ADD_FAILURE() << "no metric " << name;
  return 0;
}

TEST(SparkplugTopic, NamespaceGroupTypeNodeDevice) {
  EXPECT_EQ(Topic("fab1", MessageType::kNBirth, "gw7"), "spBv1.0/fab1/NBIRTH/gw7");
  EXPECT_EQ(Topic("fab1", MessageType::kDData, "gw7", "pump3"), "spBv1.0/fab1/DDATA/gw7/pump3");
  EXPECT_EQ(Topic("g", MessageType::kNDeath, "n"), "spBv1.0/g/NDEATH/n");
  EXPECT_EQ(Topic("g", MessageType::kNCmd, "n"), "spBv1.0/g/NCMD/n");
}

TEST(SparkplugTopic, IdsThatWouldSplitOrWildcardTheTopicAreRefused) {
  EXPECT_TRUE(ValidId("pump-3_a.b"));
  EXPECT_FALSE(ValidId(""));
  EXPECT_FALSE(ValidId("a/b"));
  EXPECT_FALSE(ValidId("a+"));
  EXPECT_FALSE(ValidId("#"));
  EXPECT_FALSE(ValidId("a\nb"));
  EXPECT_FALSE(ValidId(std::string(256, 'x')));
}

TEST(SparkplugMetrics, EveryPublishedFieldOnceAndEachNodeByName) {
  const std::vector<MetricSpec> metrics = DeviceMetrics(kNodes);
  std::set<std::string> names;
  for (const MetricSpec& m : metrics) EXPECT_TRUE(names.insert(m.name).second) << m.name;
  std::size_t fields = 0;
  for (const PublishedField& f : PublishedFields()) {
    const bool node_indexed = f.name == protocol::kNodeIndexKey ||
                              f.name == protocol::kNodeTempKey || f.name == protocol::kNodeSdKey;
    EXPECT_EQ(names.count(std::string(f.name)), node_indexed ? 0U : 1U) << f.name;
    if (node_indexed) continue;
    ++fields;
    const MetricSpec& m = metrics[IndexOf(metrics, std::string(f.name))];
    EXPECT_EQ(m.unit, f.unit) << f.name;
    EXPECT_EQ(m.type, f.csv.kind == CsvFormat::Kind::kWord ? DataType::kUInt32 : DataType::kDouble)
        << f.name;
  }
  ASSERT_EQ(metrics.size(), fields + 2 * kNodes.size());
  EXPECT_EQ(metrics[fields].name, "winding_degC");
  EXPECT_EQ(metrics[fields].unit, "degC");
  EXPECT_EQ(metrics[fields + 3].name, "rotor_sd_K");
  EXPECT_EQ(metrics[fields + 3].unit, "K");
  EXPECT_EQ(metrics[IndexOf(metrics, "alarm_level")].type, DataType::kUInt32);
}

TEST(SparkplugMetrics, ValuesAreTheFieldsOwnAndTheNodes) {
  const estimators::PumpEstimate e = SomeEstimate();
  FieldSource s;
  s.estimate = &e;
  s.uptime_s = 12.0;
  const std::vector<MetricSpec> metrics = DeviceMetrics(kNodes);
  std::vector<double> values(metrics.size());
  FillDeviceValues(s, values);
  for (const PublishedField& f : PublishedFields()) {
    if (f.name == protocol::kNodeIndexKey || f.name == protocol::kNodeTempKey ||
        f.name == protocol::kNodeSdKey)
      continue;
    const double want = f.value(s);
    const double got = values[IndexOf(metrics, std::string(f.name))];
    if (std::isnan(want)) {
      EXPECT_TRUE(std::isnan(got)) << f.name;
    } else {
      EXPECT_EQ(got, want) << f.name;
    }
  }
  EXPECT_EQ(values[IndexOf(metrics, "winding_resistance_degC")], 81.25);
  EXPECT_EQ(values[IndexOf(metrics, "alarm_level")], 1.0);
  EXPECT_EQ(values[IndexOf(metrics, "uptime_s")], 12.0);
  EXPECT_EQ(values[IndexOf(metrics, "winding_degC")], 40.0);
  EXPECT_EQ(values[IndexOf(metrics, "rotor_sd_K")], 2.0);
  std::vector<double> short_values(metrics.size() - 1);
  EXPECT_THROW(FillDeviceValues(s, short_values), std::out_of_range);
  std::vector<double> long_values(metrics.size() + 1);
  EXPECT_THROW(FillDeviceValues(s, long_values), std::out_of_range);
}

TEST(SparkplugEncoder, NodeBirthAndDeathCarryTheSession) {
  Encoder enc({});
  const pb::Payload birth = Decode(enc.NodeBirth(7, 1'700'000'000'123));
  EXPECT_EQ(birth.seq(), 0U);
  EXPECT_EQ(birth.timestamp(), 1'700'000'000'123U);
  ASSERT_EQ(birth.metrics_size(), 2);
  EXPECT_EQ(birth.metrics(0).name(), "bdSeq");
  EXPECT_EQ(birth.metrics(0).datatype(), static_cast<std::uint32_t>(pb::Int64));
  EXPECT_EQ(birth.metrics(0).long_value(), 7U);
  EXPECT_EQ(birth.metrics(1).name(), "Node Control/Rebirth");
  EXPECT_EQ(birth.metrics(1).datatype(), static_cast<std::uint32_t>(pb::Boolean));
  EXPECT_TRUE(birth.metrics(1).has_boolean_value());
  EXPECT_FALSE(birth.metrics(1).boolean_value());

  const pb::Payload death = Decode(Encoder::NodeDeath(7));
  EXPECT_FALSE(death.has_seq());
  EXPECT_FALSE(death.has_timestamp());
  ASSERT_EQ(death.metrics_size(), 1);
  EXPECT_EQ(death.metrics(0).name(), "bdSeq");
  EXPECT_EQ(death.metrics(0).long_value(), 7U);
}

// Sparkplug 3.0.0, tck-id-message-flow-edge-node-birth-publish-will-message-payload-bdSeq: each
// CONNECT packet's will carries the previous CONNECT's bdSeq + 1, 255 wrapping to 0; attempts
// that sent no CONNECT use no number; the NBIRTH and NDEATH of a session carry its CONNECT's.
TEST(SparkplugBdSeq, OnePerConnectPacketWrappingAt255) {
  BdSeq bd;
  EXPECT_EQ(bd.ForNextConnect(), 0U);
  // Three attempts with the broker unreachable: no CONNECT went out, the number is kept.
  for (int k = 0; k < 3; ++k) EXPECT_EQ(bd.ForNextConnect(), 0U);
  bd.ConnectSent();
  EXPECT_EQ(bd.Current(), 0U);  // the session's NBIRTH and NDEATH
  EXPECT_EQ(bd.ForNextConnect(), 1U);
  // A CONNECT the broker refused (or a session lost before its NBIRTH) still used its number.
  bd.ConnectSent();
  bd.ConnectSent();
  EXPECT_EQ(bd.Current(), 2U);
  EXPECT_EQ(bd.ForNextConnect(), 3U);
  std::vector<std::uint64_t> seen;
  for (int k = 3; k < 260; ++k) {
    const std::uint64_t will = bd.ForNextConnect();
    bd.ConnectSent();
    EXPECT_EQ(bd.Current(), will);
    seen.push_back(will);
  }
  EXPECT_EQ(seen[252], 255U);  // the CONNECT after 255 carries 0
  EXPECT_EQ(seen[253], 0U);
  EXPECT_EQ(seen.back(), 3U);
  // The will and the birth of a session carry the same value.
  Encoder enc({});
  EXPECT_EQ(Decode(Encoder::NodeDeath(bd.Current())).metrics(0).long_value(),
            Decode(enc.NodeBirth(bd.Current(), 1)).metrics(0).long_value());
}

class SparkplugSession : public ::testing::Test {
 protected:
  SparkplugSession()
      : metrics_(DeviceMetrics(kNodes)),
        enc_({{"pump1", metrics_}, {"pump2", metrics_}}),
        e_(SomeEstimate()),
        values_(metrics_.size()) {
    source_.estimate = &e_;
    FillDeviceValues(source_, values_);
  }
  std::vector<MetricSpec> metrics_;
  Encoder enc_;
  estimators::PumpEstimate e_;
  FieldSource source_;
  std::vector<double> values_;
};

TEST_F(SparkplugSession, DeviceBirthNamesTypesUnitsAliasesAndValues) {
  Decode(enc_.NodeBirth(0, 1000));
  const pb::Payload b1 = Decode(enc_.DeviceBirth(0, values_, 2000));
  const pb::Payload b2 = Decode(enc_.DeviceBirth(1, values_, 2000));
  EXPECT_EQ(b1.seq(), 1U);
  EXPECT_EQ(b2.seq(), 2U);
  ASSERT_EQ(b1.metrics_size(), static_cast<int>(metrics_.size()));
  std::set<std::uint64_t> aliases;
  for (const pb::Payload* b : {&b1, &b2}) {
    for (int k = 0; k < b->metrics_size(); ++k) {
      const auto& m = b->metrics(k);
      const MetricSpec& spec = metrics_[static_cast<std::size_t>(k)];
      EXPECT_TRUE(aliases.insert(m.alias()).second) << "alias " << m.alias() << " twice";
      EXPECT_EQ(m.name(), spec.name);
      EXPECT_EQ(m.datatype(), static_cast<std::uint32_t>(spec.type)) << spec.name;
      EXPECT_EQ(m.timestamp(), 2000U);
      if (spec.unit.empty()) {
        EXPECT_FALSE(m.has_properties()) << spec.name;
      } else {
        ASSERT_EQ(m.properties().keys_size(), 1) << spec.name;
        EXPECT_EQ(m.properties().keys(0), "engUnit");
        EXPECT_EQ(m.properties().values(0).string_value(), spec.unit);
      }
      const double v = values_[static_cast<std::size_t>(k)];
      if (std::isnan(v)) {
        EXPECT_TRUE(m.is_null()) << spec.name;
        EXPECT_EQ(m.value_case(), pb::Payload::Metric::VALUE_NOT_SET) << spec.name;
      } else if (spec.type == DataType::kUInt32) {
        EXPECT_EQ(m.int_value(), static_cast<std::uint32_t>(v)) << spec.name;
      } else {
        EXPECT_EQ(m.double_value(), v) << spec.name;  // infinity included (time to trip)
      }
    }
  }
  const auto level = IndexOf(metrics_, "alarm_level");
  EXPECT_EQ(b1.metrics(static_cast<int>(level)).int_value(), 1U);
  EXPECT_TRUE(
      std::isinf(b1.metrics(static_cast<int>(IndexOf(metrics_, "time_to_trip_s"))).double_value()));
}

TEST_F(SparkplugSession, DeviceDataCarriesOnlyWhatChangedByAlias) {
  enc_.NodeBirth(0, 1000);
  enc_.DeviceBirth(0, values_, 1000);
  EXPECT_EQ(enc_.DeviceData(0, values_, 2000), "") << "nothing changed, nothing to send";
  e_.node_degC[1] = 51.5;
  e_.alarm.level = estimators::AlarmLevel::kTrip;
  e_.winding_resistance_degC = kNaN;  // no longer available
  FillDeviceValues(source_, values_);
  const pb::Payload d = Decode(enc_.DeviceData(0, values_, 3000));
  EXPECT_EQ(d.seq(), 2U);
  EXPECT_EQ(d.timestamp(), 3000U);
  std::map<std::uint64_t, const pb::Payload::Metric*> by_alias;
  for (const auto& m : d.metrics()) {
    EXPECT_FALSE(m.has_name()) << "DDATA goes by alias";
    by_alias[m.alias()] = &m;
  }
  // winding_resistance_sd_K follows its temperature to "not available".
  ASSERT_EQ(by_alias.size(), 4U);
  const auto* rotor = by_alias.at(Alias(0, IndexOf(metrics_, "rotor_degC")));
  EXPECT_EQ(rotor->double_value(), 51.5);
  EXPECT_EQ(by_alias.at(Alias(0, IndexOf(metrics_, "alarm_level")))->int_value(), 2U);
  EXPECT_TRUE(by_alias.at(Alias(0, IndexOf(metrics_, "winding_resistance_degC")))->is_null());
  EXPECT_TRUE(by_alias.at(Alias(0, IndexOf(metrics_, "winding_resistance_sd_K")))->is_null());
  // Unchanged NaN is not a change either.
  EXPECT_EQ(enc_.DeviceData(0, values_, 4000), "");
}

TEST_F(SparkplugSession, DeviceDataWithEveryMetricCarriesAllOfThem) {
  enc_.NodeBirth(0, 1000);
  enc_.DeviceBirth(0, values_, 1000);
  // Nothing changed since the birth: still every metric, by alias, with the step's time.
  const pb::Payload d = Decode(enc_.DeviceData(0, values_, 2000, true));
  ASSERT_EQ(d.metrics_size(), static_cast<int>(metrics_.size()));
  for (int k = 0; k < d.metrics_size(); ++k) {
    EXPECT_EQ(d.metrics(k).alias(), Alias(0, static_cast<std::size_t>(k)));
    EXPECT_EQ(d.metrics(k).timestamp(), 2000U);
  }
  EXPECT_EQ(d.seq(), 2U);
  EXPECT_EQ(enc_.DeviceData(0, values_, 3000), "") << "then by change again";
}

TEST_F(SparkplugSession, SeqWrapsAfter255AndNodeBirthStartsAgain) {
  enc_.NodeBirth(0, 0);
  enc_.DeviceBirth(0, values_, 0);  // seq 1
  for (int k = 2; k <= 300; ++k) {
    values_[0] = k;
    const pb::Payload d = Decode(enc_.DeviceData(0, values_, static_cast<std::uint64_t>(k)));
    ASSERT_EQ(d.seq(), static_cast<std::uint64_t>(k % 256)) << k;
  }
  EXPECT_EQ(Decode(enc_.NodeBirth(1, 0)).seq(), 0U);
  // After a rebirth the devices are born again before any data.
  EXPECT_THROW(enc_.DeviceData(0, values_, 0), std::logic_error);
  const pb::Payload b = Decode(enc_.DeviceBirth(0, values_, 0));
  EXPECT_EQ(b.seq(), 1U);
  EXPECT_EQ(b.metrics_size(), static_cast<int>(metrics_.size()));
}

TEST_F(SparkplugSession, WrongDeviceOrValueCountThrows) {
  enc_.NodeBirth(0, 0);
  EXPECT_THROW(enc_.DeviceBirth(2, values_, 0), std::out_of_range);
  std::vector<double> fewer(values_.begin(), values_.end() - 1);
  EXPECT_THROW(enc_.DeviceBirth(0, fewer, 0), std::out_of_range);
  EXPECT_THROW(enc_.DeviceData(0, values_, 0), std::logic_error);
}

}  // namespace
}  // namespace pumptherm::daemon::mqtt
