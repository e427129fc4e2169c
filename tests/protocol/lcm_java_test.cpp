// Cross-language check of the pumptherm LCM types: what C++ encodes, the Java classes of
// pumptherm_lcm_types.jar (the ones lcm-spy decodes with) decode to the same values, field by
// field, and re-encode to the same bytes. The Java side is tests/protocol/LcmJavaDump.java.
// Paths come from the build: PUMPTHERM_JAVA, PUMPTHERM_LCM_JAR, PUMPTHERM_LCM_TYPES_JAR,
// PUMPTHERM_LCM_JAVA_DUMP_JAR.

#include <gtest/gtest.h>
#include <sys/wait.h>
#include <unistd.h>

#include <cstdint>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <iterator>
#include <map>
#include <string>
#include <vector>

#include "lcm_test_messages.hpp"

namespace pumptherm::test {
namespace {

/// LCM 1.3.1's generated Java reads a string byte by byte, one char per byte (ISO-8859-1), and
/// writes it back the same way (see `_decodeRecursive` in the generated .java files): the bytes
/// survive a round trip, but Java code, lcm-spy included, sees UTF-8 text as one char per byte.
/// The dump writes those chars as UTF-8, so a C++ string `s` appears as Latin1ToUtf8(s).
std::string Latin1ToUtf8(const std::string& bytes) {
  std::string out;
  for (const char ch : bytes) {
    const auto b = static_cast<unsigned char>(ch);
    if (b < 0x80) {
      out += static_cast<char>(b);
    } else {
      out += static_cast<char>(0xC0 | (b >> 6));
      out += static_cast<char>(0x80 | (b & 0x3F));
    }
  }
  return out;
}

/// A message flattened to "Type.path" -> value, as LcmJavaDump prints it: doubles apart, so
/// that they are compared bit for bit after parsing Java's shortest round-trip text.
struct Flat {
  std::map<std::string, std::string> text;
  std::map<std::string, double> numbers;

  void Number(const std::string& path, double value) { numbers[path] = value; }
  void Integer(const std::string& path, std::int64_t value) { text[path] = std::to_string(value); }
  void Text(const std::string& path, const std::string& value) { text[path] = Latin1ToUtf8(value); }
  void Bool(const std::string& path, bool value) { text[path] = value ? "true" : "false"; }
};

std::string Index(const std::string& path, std::size_t i) {
  return path + "[" + std::to_string(i) + "]";
}

void FlattenInto(Flat& f, const std::string& p, const telemetry_t& m) {
  f.Integer(p + ".utime", m.utime);
  f.Text(p + ".pump", m.pump);
  f.Integer(p + ".node_id", m.node_id);
  f.Number(p + ".id_A", m.id_A);
  f.Number(p + ".iq_A", m.iq_A);
  f.Number(p + ".ud_V", m.ud_V);
  f.Number(p + ".uq_V", m.uq_V);
  f.Number(p + ".speed_rpm", m.speed_rpm);
  f.Integer(p + ".rolling_counter", m.rolling_counter);
  f.Integer(p + ".drive_state", m.drive_state);
  f.Number(p + ".frame_sensor_degC", m.frame_sensor_degC);
  f.Number(p + ".ambient_degC", m.ambient_degC);
  f.Number(p + ".coolant_degC", m.coolant_degC);
  f.Number(p + ".dc_link_V", m.dc_link_V);
  f.Number(p + ".status_age_s", m.status_age_s);
}

void FlattenInto(Flat& f, const std::string& p, const temperatures_t& m) {
  f.Integer(p + ".utime", m.utime);
  f.Text(p + ".pump", m.pump);
  f.Number(p + ".resistance_ohm", m.resistance_ohm);
  f.Number(p + ".resistance_sd_ohm", m.resistance_sd_ohm);
  f.Number(p + ".flux_Wb", m.flux_Wb);
  f.Number(p + ".flux_sd_Wb", m.flux_sd_Wb);
  f.Number(p + ".winding_resistance_degC", m.winding_resistance_degC);
  f.Number(p + ".winding_resistance_sd_K", m.winding_resistance_sd_K);
  f.Number(p + ".magnet_flux_degC", m.magnet_flux_degC);
  f.Number(p + ".magnet_flux_sd_K", m.magnet_flux_sd_K);
  f.Integer(p + ".ident_status", m.ident_status);
  f.Integer(p + ".num_nodes", m.num_nodes);
  for (std::size_t i = 0; i < m.node_names.size(); ++i) {
    f.Text(Index(p + ".node_names", i), m.node_names[i]);
    f.Number(Index(p + ".node_degC", i), m.node_degC[i]);
    f.Number(Index(p + ".node_sd_K", i), m.node_sd_K[i]);
  }
  f.Number(p + ".nis", m.nis);
  f.Integer(p + ".filter_status", m.filter_status);
}

void FlattenInto(Flat& f, const std::string& p, const alarm_t& m) {
  f.Integer(p + ".utime", m.utime);
  f.Text(p + ".pump", m.pump);
  f.Integer(p + ".level", m.level);
  f.Number(p + ".time_to_trip_s", m.time_to_trip_s);
  f.Text(p + ".forecast_node", m.forecast_node);
  f.Integer(p + ".num_conditions", m.num_conditions);
  for (std::size_t i = 0; i < m.conditions.size(); ++i) {
    const std::string c = Index(p + ".conditions", i);
    f.Integer(c + ".level", m.conditions[i].level);
    f.Integer(c + ".reason", m.conditions[i].reason);
    f.Text(c + ".node", m.conditions[i].node);
    f.Number(c + ".value_degC", m.conditions[i].value_degC);
    f.Number(c + ".threshold_degC", m.conditions[i].threshold_degC);
    f.Number(c + ".rate_K_per_s", m.conditions[i].rate_K_per_s);
    f.Integer(c + ".since_utime", m.conditions[i].since_utime);
    f.Bool(c + ".latched", m.conditions[i].latched);
  }
  f.Integer(p + ".mismatch_state", m.mismatch_state);
  f.Integer(p + ".mismatch_effect", m.mismatch_effect);
  f.Number(p + ".mismatch_value", m.mismatch_value);
  f.Integer(p + ".mismatch_since_utime", m.mismatch_since_utime);
}

void FlattenInto(Flat& f, const std::string& p, const alarm_clear_t& m) {
  f.Integer(p + ".utime", m.utime);
  f.Text(p + ".gateway", m.gateway);
  f.Text(p + ".pump", m.pump);
  f.Text(p + ".node", m.node);
  f.Text(p + ".key_id", m.key_id);
  f.Text(p + ".comment", m.comment);
  f.Integer(p + ".counter", m.counter);
  // Java's byte is signed.
  for (std::size_t i = 0; i < 32; ++i)
    f.Integer(Index(p + ".tag", i), static_cast<std::int8_t>(m.tag[i]));
  for (std::size_t i = 0; i < 64; ++i)
    f.Integer(Index(p + ".signature", i), static_cast<std::int8_t>(m.signature[i]));
}

void FlattenInto(Flat& f, const std::string& p, const alarm_clear_reply_t& m) {
  f.Integer(p + ".utime", m.utime);
  f.Text(p + ".gateway", m.gateway);
  f.Text(p + ".pump", m.pump);
  f.Text(p + ".key_id", m.key_id);
  f.Integer(p + ".counter", m.counter);
  f.Integer(p + ".result", m.result);
  f.Text(p + ".reason", m.reason);
  f.Integer(p + ".last_counter", m.last_counter);
  f.Bool(p + ".trip_latched", m.trip_latched);
  for (std::size_t i = 0; i < 64; ++i)
    f.Integer(Index(p + ".signature", i), static_cast<std::int8_t>(m.signature[i]));
}

void FlattenInto(Flat& f, const std::string& p, const gateway_health_t& m) {
  f.Integer(p + ".utime", m.utime);
  f.Number(p + ".uptime_s", m.uptime_s);
  f.Integer(p + ".num_pumps", m.num_pumps);
  f.Integer(p + ".lcm_publish_failures", m.lcm_publish_failures);
  f.Integer(p + ".clears_accepted", m.clears_accepted);
  f.Integer(p + ".clears_refused", m.clears_refused);
  f.Integer(p + ".clears_unauthenticated", m.clears_unauthenticated);
  f.Bool(p + ".mqtt_enabled", m.mqtt_enabled);
  f.Bool(p + ".mqtt_connected", m.mqtt_connected);
  f.Integer(p + ".mqtt_dropped", m.mqtt_dropped);
  f.Integer(p + ".mqtt_alarms_dropped", m.mqtt_alarms_dropped);
  f.Integer(p + ".num_interfaces", m.num_interfaces);
  for (std::size_t i = 0; i < m.interfaces.size(); ++i) {
    const std::string c = Index(p + ".interfaces", i);
    const interface_health_t& h = m.interfaces[i];
    f.Text(c + ".name", h.name);
    f.Integer(c + ".bus_state", h.bus_state);
    f.Number(c + ".rx_frames_per_s", h.rx_frames_per_s);
    f.Number(c + ".tx_frames_per_s", h.tx_frames_per_s);
    f.Integer(c + ".rx_frames", h.rx_frames);
    f.Integer(c + ".tx_frames", h.tx_frames);
    f.Integer(c + ".rx_dropped", h.rx_dropped);
    f.Integer(c + ".tx_dropped", h.tx_dropped);
    f.Integer(c + ".rx_rejected", h.rx_rejected);
    f.Integer(c + ".error_frames", h.error_frames);
    f.Integer(c + ".reopens", h.reopens);
    f.Integer(c + ".rx_second_sender", h.rx_second_sender);
  }
}

std::vector<char> ReadBytes(const std::filesystem::path& path) {
  std::ifstream in(path, std::ios::binary);
  return {std::istreambuf_iterator<char>(in), std::istreambuf_iterator<char>()};
}

/// One message to check: its encoding is written to `<dir>/<name>.in`, Java writes `<name>.out`.
struct Case {
  std::string name;
  std::string type;
  std::vector<char> bytes;
};

class LcmJava : public ::testing::Test {
 protected:
  void SetUp() override {
    dir_ = std::filesystem::temp_directory_path() /
           ("pumptherm_lcm_java_" + std::to_string(::getpid()));
    std::filesystem::create_directories(dir_);
  }
  void TearDown() override { std::filesystem::remove_all(dir_); }

  template <typename Message>
  void Add(const Message& message) {
    Case c;
    c.type = Message::getTypeName();
    c.name = std::to_string(cases_.size()) + "_" + c.type;
    c.bytes.resize(static_cast<std::size_t>(message.getEncodedSize()));
    ASSERT_EQ(message.encode(c.bytes.data(), 0, static_cast<int>(c.bytes.size())),
              static_cast<int>(c.bytes.size()));
    std::ofstream(dir_ / (c.name + ".in"), std::ios::binary)
        .write(c.bytes.data(), static_cast<std::streamsize>(c.bytes.size()));
    FlattenInto(expected_.emplace_back(), c.type, message);
    cases_.push_back(c);
  }

  /// Runs the Java helper once over every case; returns the dump, one map per case.
  std::vector<std::map<std::string, std::string>> RunJava() {
    const std::filesystem::path dump = dir_ / "dump.txt";
    std::string command = std::string("'") + PUMPTHERM_JAVA + "' -cp '" + PUMPTHERM_LCM_JAR + ":" +
                          PUMPTHERM_LCM_TYPES_JAR + ":" + PUMPTHERM_LCM_JAVA_DUMP_JAR +
                          "' LcmJavaDump '" + dump.string() + "'";
    for (const Case& c : cases_) {
      command += " " + c.type + " '" + (dir_ / (c.name + ".in")).string() + "' '" +
                 (dir_ / (c.name + ".out")).string() + "'";
    }
    const int status = std::system(command.c_str());
    EXPECT_EQ(status, 0) << command;
    // Split the dump into cases: each starts with a line "#<type>".
    std::vector<std::map<std::string, std::string>> result;
    std::ifstream in(dump);
    std::string line;
    while (std::getline(in, line)) {
      if (!line.empty() && line[0] == '#') {
        EXPECT_LT(result.size(), cases_.size()) << "more cases in the dump than sent";
        if (result.size() < cases_.size()) {
          EXPECT_EQ(line.substr(1), cases_[result.size()].type);
        }
        result.emplace_back();
        continue;
      }
      const std::size_t eq = line.find('=');
      if (eq == std::string::npos) {
        ADD_FAILURE() << "dump line without '=': " << line;
        continue;
      }
      if (result.empty()) {
        ADD_FAILURE() << "dump does not start with a case line: " << line;
        continue;
      }
      result.back()[line.substr(0, eq)] = line.substr(eq + 1);
    }
    return result;
  }

  std::filesystem::path dir_;
  std::vector<Case> cases_;
  std::vector<Flat> expected_;
};

TEST_F(LcmJava, JavaDecodesWhatCppEncodesAndEncodesItBack) {
  Add(SampleTelemetry());
  Add(SampleTemperatures());
  Add(SampleTemperatures({}));
  Add(SampleAlarm(2));
  Add(SampleAlarm(0));
  Add(SampleAlarmClear());
  Add(SampleAlarmClearReply());
  Add(SampleGatewayHealth(2));
  ASSERT_FALSE(HasFailure());

  const std::vector<std::map<std::string, std::string>> dumped = RunJava();
  ASSERT_EQ(dumped.size(), cases_.size());
  for (std::size_t i = 0; i < cases_.size(); ++i) {
    SCOPED_TRACE(cases_[i].name);
    EXPECT_EQ(ReadBytes(dir_ / (cases_[i].name + ".out")), cases_[i].bytes)
        << "Java re-encoding differs";
    const Flat& want = expected_[i];
    const std::map<std::string, std::string>& got = dumped[i];
    EXPECT_EQ(got.size(), want.text.size() + want.numbers.size()) << "field count";
    for (const auto& [key, value] : want.text) {
      const auto it = got.find(key);
      ASSERT_NE(it, got.end()) << key << " missing from Java's dump";
      EXPECT_EQ(it->second, value) << key;
    }
    for (const auto& [key, value] : want.numbers) {
      const auto it = got.find(key);
      ASSERT_NE(it, got.end()) << key << " missing from Java's dump";
      EXPECT_TRUE(SameBits(value, std::strtod(it->second.c_str(), nullptr)))
          << key << " = " << it->second;
    }
  }
}

// Java's decoder checks the fingerprint as C++'s does: bytes of one type are refused as another.
TEST_F(LcmJava, JavaRefusesTheWrongType) {
  const alarm_clear_t clear = SampleAlarmClear();
  std::vector<char> bytes(static_cast<std::size_t>(clear.getEncodedSize()));
  ASSERT_GT(clear.encode(bytes.data(), 0, static_cast<int>(bytes.size())), 0);
  std::ofstream(dir_ / "clear.in", std::ios::binary)
      .write(bytes.data(), static_cast<std::streamsize>(bytes.size()));
  const std::string command = std::string("'") + PUMPTHERM_JAVA + "' -cp '" + PUMPTHERM_LCM_JAR +
                              ":" + PUMPTHERM_LCM_TYPES_JAR + ":" + PUMPTHERM_LCM_JAVA_DUMP_JAR +
                              "' LcmJavaDump '" + (dir_ / "dump.txt").string() + "' alarm_t '" +
                              (dir_ / "clear.in").string() + "' '" + (dir_ / "clear.out").string() +
                              "' 2>/dev/null";
  const int status = std::system(command.c_str());
  ASSERT_TRUE(WIFEXITED(status));
  EXPECT_EQ(WEXITSTATUS(status), 1);
}

}  // namespace
}  // namespace pumptherm::test
