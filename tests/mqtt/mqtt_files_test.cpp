// CheckMqttFiles (daemon/mqtt_sink.hpp), what --check-config and the sink's start check of the
// files an [mqtt] table names: each fault in its own file, the error naming the configuration's
// file, line and key.
#include <gtest/gtest.h>
#include <sys/stat.h>

#include <cstdio>
#include <fstream>
#include <string>

#include "daemon/config.hpp"
#include "daemon/mqtt_sink.hpp"

namespace pumptherm::daemon {
namespace {

constexpr const char* kCert = "-----BEGIN CERTIFICATE-----\nMIIB\n-----END CERTIFICATE-----\n";
constexpr const char* kKey = "-----BEGIN PRIVATE KEY-----\nMIIE\n-----END PRIVATE KEY-----\n";

class MqttFiles : public ::testing::Test {
 protected:
  void SetUp() override {
    dir_ = ::testing::TempDir() + "mqtt_files_" +
           ::testing::UnitTest::GetInstance()->current_test_info()->name();
    ::mkdir(dir_.c_str(), 0700);
    Write("ca.pem", kCert, 0644);
    Write("gw.pem", kCert, 0644);
    Write("gw.key", kKey, 0600);
    Write("password", "s3cret\n", 0600);
  }
  void TearDown() override {
    for (const char* f : {"ca.pem", "gw.pem", "gw.key", "password"})
      std::remove((dir_ + "/" + f).c_str());
    ::rmdir(dir_.c_str());
  }
  void Write(const std::string& name, const std::string& text, mode_t mode) {
    const std::string path = dir_ + "/" + name;
    std::ofstream(path) << text;
    ::chmod(path.c_str(), mode);
  }
  /// CheckMqttFiles' error for the usual [mqtt] table over this test's files ("" if none).
  std::string ErrorOf() const {
    const std::string text =
        "[gateway]\nname = \"gw\"\n\n[mqtt]\nhost = \"broker.plant\"\n"
        "ca_file = \"ca.pem\"\n"    // line 6
        "cert_file = \"gw.pem\"\n"  // line 7
        "key_file = \"gw.key\"\n"   // line 8
        "username = \"gw7\"\n"
        "password_file = \"password\"\n";  // line 10
    const DaemonConfig c = ParseConfig(text, dir_ + "/p.toml");
    try {
      CheckMqttFiles(c);
    } catch (const ConfigError& e) {
      return e.what();
    }
    return "";
  }
  std::string dir_;
};

TEST_F(MqttFiles, GoodFilesPass) { EXPECT_EQ(ErrorOf(), ""); }

TEST_F(MqttFiles, NothingWithoutTheTable) {
  EXPECT_NO_THROW(CheckMqttFiles(ParseConfig("[gateway]\nname = \"gw\"\n", "p.toml")));
}

TEST_F(MqttFiles, AMissingCaNamesItsLine) {
  std::remove((dir_ + "/ca.pem").c_str());
  const std::string e = ErrorOf();
  EXPECT_NE(e.find("p.toml:6: key 'mqtt.ca_file': '" + dir_ + "/ca.pem': No such file"),
            std::string::npos)
      << e;
}

TEST_F(MqttFiles, ACaOthersMayWriteIsRefused) {
  Write("ca.pem", kCert, 0666);
  const std::string e = ErrorOf();
  EXPECT_NE(e.find("p.toml:6: key 'mqtt.ca_file':"), std::string::npos) << e;
  EXPECT_NE(e.find("may be written by its group or others (mode 0666)"), std::string::npos) << e;
}

TEST_F(MqttFiles, ACertificateThatIsNoPemIsRefused) {
  Write("gw.pem", "not a certificate\n", 0644);
  const std::string e = ErrorOf();
  EXPECT_NE(e.find("p.toml:7: key 'mqtt.cert_file':"), std::string::npos) << e;
  EXPECT_NE(e.find("no '-----BEGIN CERTIFICATE-----' (PEM) block"), std::string::npos) << e;
}

TEST_F(MqttFiles, AKeyOthersMayReadIsRefusedAsTheClearKey) {
  Write("gw.key", kKey, 0644);
  const std::string e = ErrorOf();
  EXPECT_NE(e.find("p.toml:8: key 'mqtt.key_file':"), std::string::npos) << e;
}

TEST_F(MqttFiles, AKeyFileWithACertificateInsteadIsRefused) {
  Write("gw.key", kCert, 0600);
  const std::string e = ErrorOf();
  EXPECT_NE(e.find("p.toml:8: key 'mqtt.key_file':"), std::string::npos) << e;
  EXPECT_NE(e.find("holds no PEM private key"), std::string::npos) << e;
}

TEST_F(MqttFiles, APasswordFileOthersMayReadOrEmptyIsRefused) {
  Write("password", "s3cret\n", 0640);
  std::string e = ErrorOf();
  EXPECT_NE(e.find("p.toml:10: key 'mqtt.password_file':"), std::string::npos) << e;
  Write("password", "\n", 0600);
  e = ErrorOf();
  EXPECT_NE(e.find("p.toml:10: key 'mqtt.password_file':"), std::string::npos) << e;
  EXPECT_NE(e.find("is empty"), std::string::npos) << e;
}

}  // namespace
}  // namespace pumptherm::daemon
