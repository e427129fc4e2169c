// DBC reader: every construct the reader supports on a hand-written file, errors with line and
// column, and every real DBC under ../shared/data/dbc/ loading.
#include "protocol/dbc.hpp"

#include <gtest/gtest.h>

#include <cmath>
#include <filesystem>
#include <fstream>
#include <sstream>

#include "protocol/codec.hpp"
#include "tests/protocol/dbc_files.hpp"

namespace pumptherm::protocol {
namespace {

constexpr const char* kExample = R"(VERSION "1.2"

NS_ :
	NS_DESC_
	CM_
	BA_DEF_
	SG_MUL_VAL_

BS_:

BU_: Drive Gateway Logger

VAL_TABLE_ StateTable 0 "stopped" 1 "running" 2 "fault" ;

BO_ 291 Fast: 8 Drive
 SG_ Id : 0|16@1- (0.01,0) [-327.68|327.67] "A" Gateway,Logger
 SG_ Speed : 23|16@0+ (0.5,-100) [-100|32667.5] "rpm" Gateway
 SG_ Counter : 56|4@1+ (1,0) [0|15] "" Gateway

BO_ 2147484000 Extended: 64 Drive
 SG_ Mux M : 0|8@1+ (1,0) [0|255] "" Gateway
 SG_ A m0 : 8|32@1- (1,0) [0|0] "" Gateway
 SG_ B m1 : 8|16@1+ (2,1) [0|0] "V" Gateway
 SG_ Sub m2M : 8|8@1+ (1,0) [0|0] "" Gateway
 SG_ C : 16|8@1+ (1,0) [0|0] "" Gateway
 SG_ F : 32|32@1- (1,0) [0|0] "" Gateway
 SG_ D : 64|64@1- (1,0) [0|0] "" Gateway
 SG_ Tail : 511|8@0+ (1,0) [0|0] "" Gateway

EV_ SomeVariable: 0 [0|100] "" 0 1 DUMMY_NODE_VECTOR0 Vector__XXX;

CM_ "The whole network";
CM_ BU_ Drive "The drive";
CM_ BO_ 291 "Fast telemetry";
CM_ SG_ 291 Id "d-axis current
over two lines, with a \"quote\"";
BA_DEF_ BO_ "GenMsgCycleTime" INT 0 65535;
BA_DEF_ SG_ "GenSigSNA" INT 0 2147483647;
BA_DEF_ BO_ "VFrameFormat" ENUM "StandardCAN","ExtendedCAN","StandardCAN_FD","ExtendedCAN_FD";
BA_DEF_ "BusType" STRING ;
BA_DEF_DEF_ "GenMsgCycleTime" 100;
BA_DEF_DEF_ "VFrameFormat" "StandardCAN";
BA_ "BusType" "CAN FD";
BA_ "GenMsgCycleTime" BO_ 291 10;
BA_ "VFrameFormat" BO_ 2147484000 3;
BA_ "GenSigSNA" SG_ 291 Counter 15;
VAL_ 291 Counter 0 "zero" 15 "not available" ;
SIG_VALTYPE_ 2147484000 F : 1;
SIG_VALTYPE_ 2147484000 D : 2;
SG_MUL_VAL_ 2147484000 C Sub 3-5, 7-7;
SG_MUL_VAL_ 2147484000 Sub Mux 2-2;
)";

TEST(DbcTest, ParsesEveryConstructOfTheExample) {
  const Dbc dbc = ParseDbc(kExample, "example.dbc");
  EXPECT_EQ(dbc.version, "1.2");
  EXPECT_EQ(dbc.nodes, (std::vector<std::string>{"Drive", "Gateway", "Logger"}));
  ASSERT_EQ(dbc.value_tables.count("StateTable"), 1u);
  EXPECT_EQ(dbc.value_tables.at("StateTable").at(2), "fault");
  EXPECT_EQ(dbc.comment, "The whole network");
  ASSERT_EQ(dbc.messages.size(), 2u);

  const DbcMessage& fast = dbc.messages[0];
  EXPECT_EQ(fast.id, 291u);
  EXPECT_FALSE(fast.extended);
  EXPECT_EQ(fast.name, "Fast");
  EXPECT_EQ(fast.size_bytes, 8u);
  EXPECT_EQ(fast.transmitter, "Drive");
  EXPECT_EQ(fast.comment, "Fast telemetry");
  ASSERT_TRUE(fast.cycle_time_ms.has_value());
  EXPECT_EQ(*fast.cycle_time_ms, 10.0);
  ASSERT_EQ(fast.signals.size(), 3u);
  const DbcSignal& id = fast.signals[0];
  EXPECT_EQ(id.name, "Id");
  EXPECT_EQ(id.start_bit, 0u);
  EXPECT_EQ(id.length_bits, 16u);
  EXPECT_EQ(id.byte_order, ByteOrder::kLittleEndian);
  EXPECT_TRUE(id.is_signed);
  EXPECT_DOUBLE_EQ(id.factor, 0.01);
  EXPECT_DOUBLE_EQ(id.minimum, -327.68);
  EXPECT_DOUBLE_EQ(id.maximum, 327.67);
  EXPECT_EQ(id.unit, "A");
  EXPECT_EQ(id.receivers, (std::vector<std::string>{"Gateway", "Logger"}));
  EXPECT_EQ(id.comment, "d-axis current\nover two lines, with a \"quote\"");
  const DbcSignal& speed = fast.signals[1];
  EXPECT_EQ(speed.byte_order, ByteOrder::kBigEndian);
  EXPECT_FALSE(speed.is_signed);
  EXPECT_DOUBLE_EQ(speed.offset, -100.0);
  const DbcSignal& counter = fast.signals[2];
  ASSERT_TRUE(counter.not_available_raw.has_value());
  EXPECT_EQ(*counter.not_available_raw, 15);
  EXPECT_EQ(counter.value_descriptions.at(15), "not available");

  const DbcMessage& ext = dbc.messages[1];
  EXPECT_TRUE(ext.extended);
  EXPECT_EQ(ext.id, 2147484000u - 0x80000000u);
  EXPECT_EQ(ext.size_bytes, 64u);
  ASSERT_TRUE(ext.cycle_time_ms.has_value());  // the attribute default
  EXPECT_EQ(*ext.cycle_time_ms, 100.0);
  EXPECT_EQ(std::get<std::string>(ext.attributes.at("VFrameFormat")), "ExtendedCAN_FD");
  EXPECT_EQ(std::get<std::string>(dbc.network_attributes.at("BusType")), "CAN FD");

  const auto sig = [&](const char* name) -> const DbcSignal& {
    const int i = ext.FindSignal(name);
    EXPECT_GE(i, 0) << name;
    return ext.signals[static_cast<std::size_t>(i)];
  };
  EXPECT_TRUE(sig("Mux").is_multiplexer);
  EXPECT_TRUE(sig("Mux").multiplexer_switch.empty());
  EXPECT_EQ(sig("A").multiplexer_switch, "Mux");
  ASSERT_EQ(sig("A").multiplexer_ranges.size(), 1u);
  EXPECT_EQ(sig("A").multiplexer_ranges[0].low, 0u);
  EXPECT_EQ(sig("B").multiplexer_ranges[0].high, 1u);
  EXPECT_TRUE(sig("Sub").is_multiplexer);
  EXPECT_EQ(sig("Sub").multiplexer_switch, "Mux");
  EXPECT_EQ(sig("C").multiplexer_switch, "Sub");
  ASSERT_EQ(sig("C").multiplexer_ranges.size(), 2u);
  EXPECT_EQ(sig("C").multiplexer_ranges[0].low, 3u);
  EXPECT_EQ(sig("C").multiplexer_ranges[0].high, 5u);
  EXPECT_EQ(sig("C").multiplexer_ranges[1].low, 7u);
  EXPECT_EQ(sig("F").value_type, SignalValueType::kFloat32);
  EXPECT_EQ(sig("D").value_type, SignalValueType::kFloat64);
  EXPECT_EQ(SignalEndByte(sig("Tail")), 64u);
  EXPECT_EQ(SignalEndByte(speed), 4u);  // MSB bit 23 = byte 2 bit 7, 16 bits: bytes 2 and 3
  EXPECT_TRUE(dbc.problems.empty()) << dbc.problems.front().message;
}

/// Parses `text` expecting a DbcError at `line`:`column` whose message contains `needle`.
void ExpectError(const std::string& text, int line, int column, const std::string& needle) {
  try {
    ParseDbc(text, "bad.dbc");
    ADD_FAILURE() << "no error for:\n" << text;
  } catch (const DbcError& e) {
    EXPECT_EQ(e.file(), "bad.dbc");
    EXPECT_EQ(e.line(), line) << e.what();
    EXPECT_EQ(e.column(), column) << e.what();
    EXPECT_NE(std::string(e.what()).find(needle), std::string::npos) << e.what();
  }
}

/// Parses `text` expecting it to load with exactly one problem at `line`:`column` whose message
/// contains `needle`; returns what loaded.
Dbc ExpectSkipped(const std::string& text, int line, int column, const std::string& needle) {
  Dbc dbc;
  try {
    dbc = ParseDbc(text, "bad.dbc");
  } catch (const DbcError& e) {
    ADD_FAILURE() << "refused whole: " << e.what() << "\n" << text;
    return dbc;
  }
  EXPECT_EQ(dbc.problems.size(), 1u) << text;
  if (dbc.problems.empty()) return dbc;
  EXPECT_EQ(dbc.problems[0].line, line) << dbc.problems[0].message;
  EXPECT_EQ(dbc.problems[0].column, column) << dbc.problems[0].message;
  EXPECT_NE(dbc.problems[0].message.find(needle), std::string::npos) << dbc.problems[0].message;
  return dbc;
}

TEST(DbcTest, ErrorsNameLineColumnAndWhatWasExpected) {
  // Nothing loads: the first error is thrown.
  ExpectError("BO_ 1 M: 8 X\n SG_ S : 0|8@1+ (1,0) [0|0] \"unit X\n", 2, 29, "unterminated");
  ExpectError("BO_ 1 M: 8 X\n SG_ S : 510|16@1+ (1,0) [0|0] \"\" X\n", 2, 1, "beyond 64 bytes");
  ExpectError("BO_ 536870912 M: 8 X\n", 1, 1, "above 29 bits");
  ExpectError("BO_ 1 M: 65 X\n", 1, 10, "above 64 bytes");
  ExpectError("BO_ 1 M: 8 X\n SG_ S m1 : 0|8@1+ (1,0) [0|0] \"\" X\n", 2, 1,
              "0 top-level multiplexers");
  ExpectError("12 BO_\n", 1, 1, "a DBC keyword");
}

TEST(DbcTest, MalformedStatementsAreSkippedWithWhereAndTheRestLoads) {
  const std::string next = "BO_ 2 N: 8 X\n SG_ T : 0|8@1+ (1,0) [0|0] \"\" X\n";
  auto loads_next = [](const Dbc& dbc) {
    const DbcMessage* n = dbc.FindMessage("N");
    return n != nullptr && n->signals.size() == 1 && n->signals[0].name == "T";
  };
  // One SG_ skipped: the message keeps its other signals.
  Dbc dbc = ExpectSkipped(
      "BO_ 1 M: 8 X\n SG_ S : 0|8@2+ (1,0) [0|0] \"\" X\n SG_ U : 8|8@1+ (1,0) [0|0] \"\" X\n" +
          next,
      2, 14, "byte order");
  ASSERT_NE(dbc.FindMessage("M"), nullptr);
  ASSERT_EQ(dbc.FindMessage("M")->signals.size(), 1u);
  EXPECT_EQ(dbc.FindMessage("M")->signals[0].name, "U");
  EXPECT_TRUE(loads_next(dbc));
  EXPECT_NE(dbc.problems[0].message.find("signal skipped"), std::string::npos);
  EXPECT_TRUE(loads_next(
      ExpectSkipped("BO_ 1 M: 8 X\n SG_ S : 0|8@1+ (1,0 [0|0] \"\" X\n" + next, 2, 22, "')'")));
  EXPECT_TRUE(loads_next(ExpectSkipped("BO_ 1 M: 8 X\n SG_ S : 0|0@1+ (1,0) [0|0] \"\" X\n" + next,
                                       2, 12, "1 to 64 bits")));
  dbc = ExpectSkipped(
      "BO_ 1 M: 8 X\n SG_ S : 0|8@1+ (1,0) [0|0] \"\" X\n SG_ S : 8|8@1+ (1,0) [0|0] \"\" X\n" +
          next,
      3, 6, "duplicate signal S");
  EXPECT_EQ(dbc.FindMessage("M")->signals.size(), 1u);
  // A duplicate message ID: the second message and its signals are skipped.
  dbc = ExpectSkipped("BO_ 1 M: 8 X\nBO_ 1 Dup: 8 X\n SG_ D : 0|8@1+ (1,0) [0|0] \"\" X\n" + next,
                      2, 1, "duplicate message ID");
  EXPECT_EQ(dbc.FindMessage("Dup"), nullptr);
  EXPECT_TRUE(dbc.FindMessage("M")->signals.empty());
  EXPECT_TRUE(loads_next(dbc));
  dbc = ExpectSkipped("BO_ 1 M: 65 X\n SG_ S : 0|8@1+ (1,0) [0|0] \"\" X\n" + next, 1, 10,
                      "above 64 bytes");
  EXPECT_EQ(dbc.FindMessage("M"), nullptr);
  EXPECT_TRUE(loads_next(dbc));
  // An IEEE type that does not fit the signal: the SIG_VALTYPE_ is skipped, the signal stays an
  // integer.
  dbc = ExpectSkipped(
      "BO_ 1 M: 8 X\n SG_ F : 0|16@1+ (1,0) [0|0] \"\" X\nSIG_VALTYPE_ 1 F : 1;\n" + next, 3, 20,
      "needs 32");
  EXPECT_EQ(dbc.FindMessage("M")->signals[0].value_type, SignalValueType::kInteger);
  EXPECT_TRUE(loads_next(dbc));
}

TEST(DbcTest, MessageIdsWithBit30AreSkippedWithTheirReferences) {
  // 0xC0000123: bit 31 (extended) and bit 30, which no CAN frame has. Its CM_, BA_ and VAL_
  // refer to a skipped message and add no further problems.
  const Dbc dbc = ExpectSkipped(
      "BO_ 3221225763 Bad: 8 X\n SG_ B : 0|8@1+ (1,0) [0|0] \"\" X\n"
      "BO_ 2147483940 Good: 8 X\n SG_ G : 0|8@1+ (1,0) [0|0] \"\" X\n"
      "BA_DEF_ BO_ \"GenMsgCycleTime\" INT 0 10000;\n"
      "CM_ BO_ 3221225763 \"bad\";\nCM_ SG_ 3221225763 B \"bad\";\nBA_ \"GenMsgCycleTime\" BO_ "
      "3221225763 10;\n"
      "VAL_ 3221225763 B 0 \"zero\" ;\n",
      1, 1, "above 29 bits");
  ASSERT_EQ(dbc.messages.size(), 1u);
  EXPECT_EQ(dbc.messages[0].name, "Good");
  EXPECT_TRUE(dbc.messages[0].extended);
  EXPECT_EQ(dbc.messages[0].id, 0x124u);
  EXPECT_NE(dbc.problems[0].message.find("message and its signals skipped"), std::string::npos);
}

TEST(DbcTest, CommentWithoutSemicolonIsSkippedAndTheNextStatementReads) {
  const Dbc dbc = ExpectSkipped(
      "BO_ 1 M: 8 X\n SG_ S : 0|8@1+ (1,0) [0|0] \"\" X\n SG_ T : 8|8@1+ (1,0) [0|0] \"\" X\n"
      "CM_ SG_ 1 S \"no semicolon\"\nCM_ SG_ 1 T \"fine\";\n",
      5, 1, "expected ';', found 'CM_'; the CM_ of line 4 skipped");
  const DbcMessage& m = *dbc.FindMessage("M");
  EXPECT_EQ(m.signals[0].comment, "");
  EXPECT_EQ(m.signals[1].comment, "fine");
}

TEST(DbcTest, StringGenSigSnaIsAWarningAndIgnored) {
  const Dbc dbc = ExpectSkipped(
      "BO_ 1 M: 8 X\n SG_ S : 0|12@1+ (1,0) [0|0] \"\" X\n"
      "BA_DEF_ SG_ \"GenSigSNA\" STRING ;\nBA_ \"GenSigSNA\" SG_ 1 S \"FFFh\";\n",
      4, 1, "GenSigSNA of signal S");
  EXPECT_FALSE(dbc.messages[0].signals[0].not_available_raw.has_value());
  const MessageCodec codec(dbc.messages[0]);
  std::vector<double> v(1);
  ASSERT_EQ(codec.Decode(std::vector<std::uint8_t>{0xFF, 0x0F, 0, 0, 0, 0, 0, 0}, v),
            CodecStatus::kOk);
  EXPECT_EQ(v[0], 4095.0);  // a real value, not "not available"
}

// Raw values beyond the 64-bit range are a skipped statement, not undefined behaviour in the
// conversion (dbc_reader_fuzz found a value description 4.44444e+101 under UBSan).
TEST(DbcTest, RawValuesOutsideThe64BitRangeAreErrors) {
  const std::string message = "BO_ 1 M: 8 X\n SG_ S : 0|8@1+ (1,0) [0|0] \"\" X\n";
  ExpectSkipped(message + "VAL_ 1 S 4.44444e+101 \"huge\" ;\n", 3, 10, "64-bit integer range");
  ExpectSkipped(message + "VAL_ 1 S -1e19 \"huge\" ;\n", 3, 10, "64-bit integer range");
  ExpectSkipped(
      message + "BA_DEF_ SG_ \"GenSigSNA\" FLOAT 0 1e300;\nBA_ \"GenSigSNA\" SG_ 1 S 1e30;\n", 4, 1,
      "within the 64-bit range");
  // The largest values that fit are fine.
  const Dbc dbc =
      ParseDbc(message + "VAL_ 1 S 4294967295 \"u32\" -9223372036854775808 \"min\" ;\n", "ok.dbc");
  ASSERT_EQ(dbc.messages.size(), 1u);
}

TEST(DbcTest, SkipsUnusedSectionsAndReportsDanglingReferences) {
  const Dbc dbc = ParseDbc(
      "BO_ 1 M: 1 X\n SG_ S : 0|12@1+ (1,0) [0|0] \"\" X\n"
      "SIG_GROUP_ 1 G 1 : S;\nBO_TX_BU_ 1 : X,Y;\nBA_DEF_REL_ BU_SG_REL_ \"R\" INT 0 1;\n"
      "VAL_ 1 Missing 0 \"a\" ;\nCM_ BO_ 99 \"nobody\";\n",
      "odd.dbc");
  ASSERT_EQ(dbc.messages.size(), 1u);
  ASSERT_EQ(dbc.problems.size(), 3u);
  // Sorted by line.
  EXPECT_EQ(dbc.problems[0].line, 2);  // 12 bits in a 1-byte message
  EXPECT_NE(dbc.problems[0].message.find("message is 1 bytes"), std::string::npos);
  EXPECT_EQ(dbc.problems[1].line, 6);
  EXPECT_NE(dbc.problems[1].message.find("Missing"), std::string::npos);
  EXPECT_EQ(dbc.problems[2].line, 7);
}

TEST(DbcTest, ReadsAnIdAbove11BitsWithoutTheFlagAs29Bit) {
  // chrysler_cusw.dbc (opendbc) writes BSM_LEFT as "BO_ 103596083": 0x62CC033 without bit 31.
  const Dbc dbc = ParseDbc("BO_ 103596083 BSM_LEFT: 8 XXX\n", "x.dbc");
  ASSERT_EQ(dbc.messages.size(), 1u);
  EXPECT_TRUE(dbc.messages[0].extended);
  EXPECT_EQ(dbc.messages[0].id, 0x62CC033u);
  ASSERT_EQ(dbc.problems.size(), 1u);
  EXPECT_EQ(dbc.problems[0].line, 1);
}

TEST(DbcTest, RejectsMultiplexerCycles) {
  ExpectError(
      "BO_ 1 M: 8 X\n SG_ A m1M : 0|8@1+ (1,0) [0|0] \"\" X\n SG_ B m1M : 8|8@1+ (1,0) [0|0] \"\" "
      "X\n"
      "SG_MUL_VAL_ 1 A B 1-1;\nSG_MUL_VAL_ 1 B A 1-1;\n",
      2, 1, "multiplexer cycle");
}

TEST(DbcTest, EveryRealDbcLoads) {
  const auto files = test::RealDbcFiles();
  if (files.empty()) GTEST_SKIP() << "no DBC files under " << test::SharedDbcDir();
  for (const auto& path : files) {
    SCOPED_TRACE(path.string());
    const Dbc dbc = ParseDbc(test::ReadFile(path), path.string());
    EXPECT_FALSE(dbc.messages.empty());
    for (const auto& m : dbc.messages) {
      for (const auto& s : m.signals) {
        EXPECT_LE(SignalEndByte(s), 64u);
        if (!s.multiplexer_switch.empty()) {
          EXPECT_GE(m.FindSignal(s.multiplexer_switch), 0);
        }
      }
    }
  }
}

// Vector's tools write names of at most 32 characters in the statements and the long name as
// an attribute; the long name is the name (as cantools and canmatrix show it), statements that
// refer to the short name still apply, and a long name that would repeat another keeps the
// short one. The fixture is ours (tests/protocol/dbc/long_names.dbc), modelled on the cases of
// cantools' tests/files/dbc/long_names.dbc; codec_canmatrix_test checks the names against
// canmatrix.
TEST(DbcTest, LongNamesAreTheNames) {
  const auto path = test::SourceDir() / "tests" / "protocol" / "dbc" / "long_names.dbc";
  const Dbc dbc = ParseDbc(test::ReadFile(path), "long_names.dbc");
  ASSERT_EQ(dbc.nodes.size(), 2u);
  EXPECT_EQ(dbc.nodes[0], "TurboPumpDriveController_Hall_B_Line_4");
  EXPECT_EQ(dbc.node_comments.at("TurboPumpDriveController_Hall_B_Line_4"),
            "the drive, by its short name");
  const DbcMessage* fast = dbc.FindMessage("TurboPumpFastTelemetryCurrents_DirectAndQuadrature");
  ASSERT_NE(fast, nullptr);
  EXPECT_EQ(fast->transmitter, "TurboPumpDriveController_Hall_B_Line_4");
  EXPECT_EQ(fast->comment, "the fast telemetry, by its ID");
  EXPECT_FALSE(fast->attributes.contains("SystemMessageLongSymbol"));
  ASSERT_EQ(fast->signals.size(), 3u);
  EXPECT_EQ(fast->signals[0].name, "StatorCurrentDirectAxisAmpere_Id");
  EXPECT_EQ(fast->signals[0].comment, "Id, by its short name");
  EXPECT_EQ(fast->signals[0].not_available_raw, -32768);  // BA_ by the short name
  EXPECT_EQ(fast->signals[1].name, "StatorCurrentQuadratureAxisAmpere_Iq");
  EXPECT_FALSE(fast->signals[1].attributes.contains("SystemSignalLongSymbol"));
  EXPECT_EQ(fast->signals[2].name, "Counter");

  const DbcMessage* table = dbc.FindMessage("GatewayNodeTemperatureTable_ByThermalNetworkNode");
  ASSERT_NE(table, nullptr);
  EXPECT_EQ(table->signals[0].name, "ThermalNetworkNodeIndexMultiplexer");
  EXPECT_EQ(table->signals[0].receivers,
            std::vector<std::string>{"TurboPumpDriveController_Hall_B_Line_4"});
  EXPECT_EQ(table->signals[0].value_descriptions.at(1), "stator");
  EXPECT_EQ(table->signals[1].name, "NodeTemperatureDegreesCelsius_Frame");
  // The multiplexed signals follow their switch's new name, and still decode by it.
  EXPECT_EQ(table->signals[2].multiplexer_switch, "ThermalNetworkNodeIndexMultiplexer");
  const MessageCodec codec(*table);
  const std::uint8_t frame[8] = {1, 0, 0x10, 0x27, 0, 0, 0, 0};  // node 1, raw 10000
  std::vector<double> values(codec.signal_count());
  ASSERT_EQ(codec.Decode(frame, values), CodecStatus::kOk);
  EXPECT_TRUE(std::isnan(values[1]));
  EXPECT_NEAR(values[2], 50.0, 1e-9);

  // A long name that is another signal's name: the short name stays, with a warning.
  const DbcMessage* short_name = dbc.FindMessage("ShortName");
  ASSERT_NE(short_name, nullptr);
  EXPECT_EQ(short_name->signals[2].name, "WouldRepeatTaken");
  bool warned = false;
  for (const auto& p : dbc.problems)
    warned = warned || p.message.find("is the name of another signal") != std::string::npos;
  EXPECT_TRUE(warned);
  // The environment variable's long name names nothing this reader keeps: no problem about it.
  for (const auto& p : dbc.problems) EXPECT_EQ(p.message.find("EnvVar"), std::string::npos);
}

TEST(DbcTest, PumpthermFrameSetIsCompleteAndConsistent) {
  const Dbc dbc = ParseDbc(test::ReadFile(test::PumpthermDbc()), "protocol/pumptherm.dbc");
  EXPECT_TRUE(dbc.problems.empty())
      << dbc.problems.front().line << ": " << dbc.problems.front().message;
  EXPECT_EQ(dbc.messages.size(), 12u);
  for (const auto& m : dbc.messages) {
    SCOPED_TRACE(m.name);
    ASSERT_TRUE(m.cycle_time_ms.has_value());
    EXPECT_GT(*m.cycle_time_ms, 0.0);
    EXPECT_FALSE(m.comment.empty());
    EXPECT_EQ(m.id % 16, 0u) << "node IDs 0..15 are added to the ID";
    EXPECT_LE(m.size_bytes, 8u);  // classic CAN
    for (const auto& s : m.signals) {
      SCOPED_TRACE(s.name);
      EXPECT_FALSE(s.comment.empty()) << "resolution and range rationale";
      EXPECT_LE(SignalEndByte(s), m.size_bytes);
      // The declared physical range lies inside what the raw field can carry, and the
      // "not available" raw value lies outside the declared range.
      const double raw_lo =
          s.is_signed ? -std::ldexp(1.0, static_cast<int>(s.length_bits) - 1) : 0.0;
      const double raw_hi = s.is_signed ? std::ldexp(1.0, static_cast<int>(s.length_bits) - 1) - 1
                                        : std::ldexp(1.0, static_cast<int>(s.length_bits)) - 1;
      EXPECT_GE(s.minimum, raw_lo * s.factor + s.offset - 1e-9);
      EXPECT_LE(s.maximum, raw_hi * s.factor + s.offset + 1e-9);
      if (s.not_available_raw) {
        const double sna = static_cast<double>(*s.not_available_raw) * s.factor + s.offset;
        EXPECT_TRUE(sna < s.minimum - 1e-9 || sna > s.maximum + 1e-9) << sna;
      }
    }
  }
  // No two messages of different pumps collide: blocks of 16 IDs are disjoint.
  for (std::size_t i = 0; i < dbc.messages.size(); ++i) {
    for (std::size_t j = i + 1; j < dbc.messages.size(); ++j) {
      EXPECT_NE(dbc.messages[i].id / 16, dbc.messages[j].id / 16);
    }
  }
}

TEST(DbcTest, Model3HasItsDocumentedContent) {
  const auto path = test::SharedDbcDir() / "model3dbc" / "Model3CAN.dbc";
  if (!std::filesystem::exists(path)) GTEST_SKIP() << path << " absent";
  const Dbc dbc = ParseDbc(test::ReadFile(path), path.string());
  // ../shared/data/README.md: 148 messages; drive-inverter temperatures in 0x315 and 0x376.
  EXPECT_EQ(dbc.messages.size(), 148u);
  EXPECT_NE(dbc.FindMessage(0x315, false), nullptr);
  EXPECT_NE(dbc.FindMessage(0x376, false), nullptr);
}

}  // namespace
}  // namespace pumptherm::protocol
