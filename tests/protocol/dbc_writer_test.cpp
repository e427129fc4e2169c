// DBC writer: numbers as plain decimals that read back exactly, long and odd names written as
// Vector's tools write them, and parse -> write -> parse giving the same database for every DBC
// this project has (the shared real-world files, the shipped frame set, the test fixtures).
#include "protocol/dbc_writer.hpp"

#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <string>

#include "protocol/dbc.hpp"
#include "tests/protocol/dbc_files.hpp"

namespace pumptherm::protocol {
namespace {

TEST(DbcWriterTest, NumbersArePlainDecimalsThatReadBackExactly) {
  EXPECT_EQ(DbcNumber(0.00001), "0.00001");
  EXPECT_EQ(DbcNumber(-50.0), "-50");
  EXPECT_EQ(DbcNumber(0.1), "0.1");
  EXPECT_EQ(DbcNumber(605.34), "605.34");
  EXPECT_EQ(DbcNumber(4294967294.0), "4294967294");
  EXPECT_EQ(DbcNumber(-2147483648.0), "-2147483648");
  EXPECT_EQ(DbcNumber(1.5e20), "150000000000000000000");
  EXPECT_EQ(DbcNumber(1.25e-7), "0.000000125");
  for (double v : {1e-300, 3.0517578125e-05, 1.0 / 3.0, 123456789.123, -9.87654321e-12, 1e22}) {
    const std::string text = DbcNumber(v);
    EXPECT_EQ(text.find_first_of("eE"), std::string::npos) << text;
    EXPECT_EQ(std::stod(text), v) << text;
  }
  EXPECT_THROW(DbcNumber(std::nan("")), std::invalid_argument);
}

/// Everything the reader keeps, compared field by field (problems aside: the writer does not
/// repeat a file's defects).
void ExpectSameDbc(const Dbc& a, const Dbc& b) {
  EXPECT_EQ(a.version, b.version);
  EXPECT_EQ(a.nodes, b.nodes);
  EXPECT_EQ(a.value_tables, b.value_tables);
  EXPECT_EQ(a.network_attributes, b.network_attributes);
  EXPECT_EQ(a.node_attributes, b.node_attributes);
  EXPECT_EQ(a.node_comments, b.node_comments);
  EXPECT_EQ(a.comment, b.comment);
  // The writer declares the long-name attributes it writes for names over 32 characters.
  std::vector<DbcAttributeDefinition> b_definitions;
  for (const auto& d : b.attribute_definitions) {
    const bool added = d.name.starts_with("System") && d.name.ends_with("LongSymbol") &&
                       std::none_of(a.attribute_definitions.begin(), a.attribute_definitions.end(),
                                    [&](const auto& x) { return x.name == d.name; });
    if (!added) b_definitions.push_back(d);
  }
  ASSERT_EQ(a.attribute_definitions.size(), b_definitions.size());
  for (std::size_t i = 0; i < a.attribute_definitions.size(); ++i) {
    const auto& x = a.attribute_definitions[i];
    const auto& y = b_definitions[i];
    EXPECT_EQ(x.name, y.name);
    EXPECT_EQ(x.object, y.object) << x.name;
    EXPECT_EQ(x.type, y.type) << x.name;
    EXPECT_EQ(x.minimum, y.minimum) << x.name;
    EXPECT_EQ(x.maximum, y.maximum) << x.name;
    EXPECT_EQ(x.enum_values, y.enum_values) << x.name;
    EXPECT_EQ(x.default_value, y.default_value) << x.name;
  }
  ASSERT_EQ(a.messages.size(), b.messages.size());
  for (std::size_t mi = 0; mi < a.messages.size(); ++mi) {
    const DbcMessage& m = a.messages[mi];
    const DbcMessage& n = b.messages[mi];
    SCOPED_TRACE(m.name);
    EXPECT_EQ(m.id, n.id);
    EXPECT_EQ(m.extended, n.extended);
    EXPECT_EQ(m.name, n.name);
    EXPECT_EQ(m.size_bytes, n.size_bytes);
    EXPECT_EQ(m.transmitter, n.transmitter);
    EXPECT_EQ(m.comment, n.comment);
    EXPECT_EQ(m.attributes, n.attributes);
    EXPECT_EQ(m.cycle_time_ms, n.cycle_time_ms);
    ASSERT_EQ(m.signals.size(), n.signals.size());
    for (std::size_t si = 0; si < m.signals.size(); ++si) {
      const DbcSignal& s = m.signals[si];
      const DbcSignal& t = n.signals[si];
      SCOPED_TRACE(s.name);
      EXPECT_EQ(s.name, t.name);
      EXPECT_EQ(s.start_bit, t.start_bit);
      EXPECT_EQ(s.length_bits, t.length_bits);
      EXPECT_EQ(s.byte_order, t.byte_order);
      EXPECT_EQ(s.is_signed, t.is_signed);
      EXPECT_EQ(s.value_type, t.value_type);
      EXPECT_EQ(s.factor, t.factor);
      EXPECT_EQ(s.offset, t.offset);
      EXPECT_EQ(s.minimum, t.minimum);
      EXPECT_EQ(s.maximum, t.maximum);
      EXPECT_EQ(s.unit, t.unit);
      EXPECT_EQ(s.receivers, t.receivers);
      EXPECT_EQ(s.is_multiplexer, t.is_multiplexer);
      EXPECT_EQ(s.multiplexer_switch, t.multiplexer_switch);
      ASSERT_EQ(s.multiplexer_ranges.size(), t.multiplexer_ranges.size());
      for (std::size_t r = 0; r < s.multiplexer_ranges.size(); ++r) {
        EXPECT_EQ(s.multiplexer_ranges[r].low, t.multiplexer_ranges[r].low);
        EXPECT_EQ(s.multiplexer_ranges[r].high, t.multiplexer_ranges[r].high);
      }
      EXPECT_EQ(s.comment, t.comment);
      EXPECT_EQ(s.value_descriptions, t.value_descriptions);
      EXPECT_EQ(s.attributes, t.attributes);
      EXPECT_EQ(s.not_available_raw, t.not_available_raw);
    }
  }
}

TEST(DbcWriterTest, EveryDbcReadsBackTheSame) {
  std::vector<std::filesystem::path> files = test::RealDbcFiles();
  const std::size_t real = files.size();
  files.push_back(test::PumpthermDbc());
  files.push_back(test::SourceDir() / "tests" / "protocol" / "candied" / "features.dbc");
  files.push_back(test::SourceDir() / "tests" / "protocol" / "dbc" / "long_names.dbc");
  std::size_t messages = 0;
  for (const auto& path : files) {
    SCOPED_TRACE(path.string());
    const Dbc first = ParseDbc(test::ReadFile(path), path.string());
    const std::string text = FormatDbc(first);
    const Dbc second = ParseDbc(text, "written");
    // The writer repeats no defect of the file (a skipped statement is not written) and adds
    // none; what is left (an attribute used without its BA_DEF_) is the file's own.
    EXPECT_LE(second.problems.size(), first.problems.size())
        << "written:" << second.problems.front().line << ": " << second.problems.front().message;
    ExpectSameDbc(first, second);
    messages += first.messages.size();
  }
  std::cout << files.size() << " files (" << real << " shared), " << messages
            << " messages read back the same\n";
}

TEST(DbcWriterTest, LongAndOddNamesAreWrittenShortWithTheirLongName) {
  Dbc dbc;
  dbc.version = "test";
  dbc.nodes = {"Turbo pump drive, hall B"};
  DbcMessage m;
  m.id = 0x123;
  m.name = "A_message_name_that_is_longer_than_thirty_two_characters";
  m.size_bytes = 8;
  m.transmitter = "Turbo pump drive, hall B";
  DbcSignal s;
  s.name = "pump3.winding_degC";
  s.length_bits = 16;
  s.factor = 0.01;
  s.offset = -50;
  s.receivers = {"Turbo pump drive, hall B"};
  m.signals.push_back(s);
  s.name = "pump3.winding_sd_K";
  s.start_bit = 16;
  m.signals.push_back(s);
  dbc.messages.push_back(m);
  const std::string text = FormatDbc(dbc);
  EXPECT_NE(text.find("BO_ 291 A_message_name_that_is_long_0000: 8 Turbo_pump_drive__hall_B_0000"),
            std::string::npos)
      << text;
  EXPECT_NE(text.find("SG_ pump3_winding_degC_0000 : 0|16@1+ (0.01,-50)"), std::string::npos)
      << text;
  EXPECT_NE(text.find("SG_ pump3_winding_sd_K_0001 : 16|16@1+"), std::string::npos) << text;
  const Dbc back = ParseDbc(text, "written");
  EXPECT_TRUE(back.problems.empty()) << back.problems.front().message;
  ASSERT_EQ(back.messages.size(), 1u);
  EXPECT_EQ(back.nodes, dbc.nodes);
  EXPECT_EQ(back.messages[0].name, m.name);
  EXPECT_EQ(back.messages[0].transmitter, m.transmitter);
  EXPECT_EQ(back.messages[0].signals[0].name, "pump3.winding_degC");
  EXPECT_EQ(back.messages[0].signals[1].name, "pump3.winding_sd_K");
  EXPECT_EQ(back.messages[0].signals[1].receivers, s.receivers);
  EXPECT_EQ(back.messages[0].signals[0].factor, 0.01);
}

}  // namespace
}  // namespace pumptherm::protocol
