// `pumptherm dbc check|decode` end to end: the built binary on protocol/pumptherm.dbc and on a
// candump log whose frames our encoder wrote.
#include <gtest/gtest.h>
#include <poll.h>
#include <sys/wait.h>
#include <unistd.h>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <string>
#include <vector>

#include "protocol/candump_log.hpp"
#include "protocol/codec.hpp"
#include "protocol/dbc.hpp"
#include "tests/common/run_command.hpp"
#include "tests/protocol/dbc_files.hpp"

namespace pumptherm::protocol {
namespace {

namespace fs = std::filesystem;

struct RunResult {
  int exit_code = -1;
  std::string out;  ///< stdout and stderr
};

RunResult RunPumptherm(const std::string& args, const std::string& stdin_file = "") {
  std::string command = std::string("'") + PUMPTHERM_BIN + "' " + args + " 2>&1";
  if (!stdin_file.empty()) command += " < '" + stdin_file + "'";
  test_files::CommandResult c = test_files::RunCommand(command);
  return {c.exit_code, std::move(c.out)};
}

fs::path TempFile(const std::string& name) {
  return fs::temp_directory_path() / ("pumptherm_cli_" + std::to_string(getpid()) + "_" + name);
}

TEST(DbcCliTest, CheckListsThePumpthermFrameSet) {
  const RunResult r = RunPumptherm("dbc check '" + test::PumpthermDbc().string() + "'");
  EXPECT_EQ(r.exit_code, 0) << r.out;
  EXPECT_NE(r.out.find("12 messages, 51 signals, 3 nodes"), std::string::npos) << r.out;
  EXPECT_NE(r.out.find("0x100 PUMP_FAST_I 8 bytes, 10 ms, from PumpDrive"), std::string::npos)
      << r.out;
  EXPECT_NE(r.out.find("n/a raw -32768"), std::string::npos) << r.out;
}

TEST(DbcCliTest, CheckNamesWhereAFileIsBroken) {
  const fs::path bad = TempFile("bad.dbc");
  std::ofstream(bad)
      << "BO_ 1 M: 8 X\n SG_ S : 0|8@1+ (1,0 [0|0] \"\" X\n SG_ T : 8|8@1+ (1,0) [0|0] \"\" X\n";
  // The broken signal is a warning; the rest loads.
  RunResult r = RunPumptherm("dbc check '" + bad.string() + "'");
  EXPECT_EQ(r.exit_code, 0) << r.out;
  EXPECT_NE(r.out.find(bad.string() + ":2:22: warning: expected ')'"), std::string::npos) << r.out;
  EXPECT_NE(r.out.find("signal skipped"), std::string::npos) << r.out;
  EXPECT_NE(r.out.find("1 messages, 1 signals"), std::string::npos) << r.out;
  // --strict: warnings fail.
  r = RunPumptherm("dbc check --strict '" + bad.string() + "'");
  EXPECT_EQ(r.exit_code, 2) << r.out;
  // Nothing loads: an error.
  std::ofstream(bad) << "BO_ 1 M: 65 X\n";
  r = RunPumptherm("dbc check '" + bad.string() + "'");
  EXPECT_EQ(r.exit_code, 2) << r.out;
  EXPECT_NE(r.out.find(bad.string() + ":1:10: message length above 64 bytes"), std::string::npos)
      << r.out;
  // An empty DBC is no frame set: --strict fails it.
  std::ofstream(bad) << "VERSION \"\"\nBU_: X\n";
  r = RunPumptherm("dbc check '" + bad.string() + "'");
  EXPECT_EQ(r.exit_code, 0) << r.out;
  EXPECT_NE(r.out.find("no messages"), std::string::npos) << r.out;
  r = RunPumptherm("dbc check --strict '" + bad.string() + "'");
  EXPECT_EQ(r.exit_code, 2) << r.out;
  fs::remove(bad);
}

TEST(DbcCliTest, ShippedDbcByItsBareName) {
  // As the config names it: a bare file name not in the working directory is the shipped file.
  const RunResult r = RunPumptherm("dbc check pumptherm.dbc");
  EXPECT_EQ(r.exit_code, 0) << r.out;
  EXPECT_NE(r.out.find("0x100 PUMP_FAST_I 8 bytes"), std::string::npos) << r.out;
}

TEST(DbcCliTest, DecodeGivesBackWhatTheEncoderWrote) {
  const Dbc dbc = ParseDbc(test::ReadFile(test::PumpthermDbc()), "pumptherm.dbc");
  const DbcMessage& fast = *dbc.FindMessage("PUMP_FAST_I");
  const MessageCodec codec(fast);
  CanFrame f;
  f.id = fast.id + 3;  // pump 3
  f.len = 8;
  const std::vector<double> values = {12.345, -0.5, 2199.11, 7};
  ASSERT_EQ(codec.Encode(values, std::span<std::uint8_t>(f.data.data(), 8)).status,
            CodecStatus::kOk);
  CanFrame short_frame = f;
  short_frame.len = 4;
  CanFrame unknown = f;
  unknown.id = 0x6FF;  // GW_HEALTH + 255: no node's (0x7F0 + n is the heartbeat's block)
  const fs::path log = TempFile("run.log");
  {
    std::ofstream out(log);
    out << FormatCandumpLine(1700000000123456, "vcan0", f) << '\n'
        << FormatCandumpLine(1700000000133456, "vcan0", short_frame) << '\n'
        << FormatCandumpLine(1700000000143456, "vcan0", unknown) << '\n';
  }
  const std::string dbc_arg = " --dbc '" + test::PumpthermDbc().string() + "' ";
  RunResult r = RunPumptherm("dbc decode --node-id-limit 16" + dbc_arg + "'" + log.string() + "'");
  EXPECT_EQ(r.exit_code, 0) << r.out;
  // 12.345 A at 5 mA per step -> raw 2469 -> 12.345; 2199.11 rad/s at 0.01 -> 2199.11.
  EXPECT_NE(
      r.out.find(R"({"time_s":1700000000.123456,"interface":"vcan0","can_id":"0x103","node":3,)"
                 R"("message":"PUMP_FAST_I","signals":{"Id_A":12.345,"Iq_A":-0.5,)"
                 R"("SpeedElec_rad_per_s":2199.11,"RollingCounter":7}})"),
      std::string::npos)
      << r.out;
  EXPECT_NE(r.out.find("1 frames decoded, 1 with IDs not in"), std::string::npos) << r.out;
  EXPECT_NE(r.out.find("(1 11-bit, 0 29-bit), 1 shorter than their message"), std::string::npos)
      << r.out;

  // CSV from stdin, one message selected.
  r = RunPumptherm("dbc decode --format csv --message PUMP_FAST_I --node-id-limit 16" + dbc_arg,
                   log.string());
  EXPECT_EQ(r.exit_code, 0) << r.out;
  EXPECT_NE(r.out.find("time_s,interface,can_id,node,message,PUMP_FAST_I.Id_A,PUMP_FAST_I.Iq_A,"
                       "PUMP_FAST_I.SpeedElec_rad_per_s,PUMP_FAST_I.RollingCounter\n"
                       "1700000000.123456,vcan0,0x103,3,PUMP_FAST_I,12.345,-0.5,2199.11,7\n"),
            std::string::npos)
      << r.out;

  // Without the node ID rule, pump 3's frame is not in the DBC.
  r = RunPumptherm("dbc decode" + dbc_arg + "'" + log.string() + "'");
  EXPECT_NE(r.out.find("0 frames decoded, 3 with IDs not in"), std::string::npos) << r.out;
  fs::remove(log);
}

TEST(DbcCliTest, DecodeSkipsAndCountsBadLogLines) {
  const fs::path log = TempFile("bad.log");
  std::ofstream(log)
      << "(1.000000) vcan0 100#0011223344556677\n(2.0) vcan0 10Z#00\n"
      << "(3.0) vcan0 40000100#0011223344556677\n(4.000000) vcan0 100#0011223344556677\n";
  const RunResult r = RunPumptherm("dbc decode --dbc pumptherm.dbc '" + log.string() + "'");
  fs::remove(log);
  EXPECT_EQ(r.exit_code, 0) << r.out;
  EXPECT_NE(
      r.out.find(log.string() + ":2:15: warning: expected a hexadecimal CAN ID; line skipped"),
      std::string::npos)
      << r.out;
  EXPECT_NE(r.out.find(log.string() + ":3:13: warning: CAN ID above 29 bits; line skipped"),
            std::string::npos)
      << r.out;
  EXPECT_NE(r.out.find("\"time_s\":4.000000"), std::string::npos) << r.out;  // reading went on
  EXPECT_NE(r.out.find("2 frames decoded, 0 with IDs not in pumptherm.dbc (0 11-bit, 0 29-bit), 0 "
                       "shorter than their message, 0 error and 0 remote frames not decoded, 2 bad "
                       "lines skipped"),
            std::string::npos)
      << r.out;
}

// pumptherm.dbc's IDs are per pump (DBC ID + node ID): without --node-id-limit a pump's frames
// are unknown, and the summary says which option decodes them.
TEST(DbcCliTest, UnknownPerPumpFramesNameTheNodeIdOption) {
  const fs::path log = TempFile("perpump.log");
  std::ofstream(log) << "(1.000000) can0 203#0622784000000207\n(2.000000) can0 6FF#00\n";
  const RunResult plain = RunPumptherm("dbc decode --dbc pumptherm.dbc '" + log.string() + "'");
  const RunResult offset =
      RunPumptherm("dbc decode --dbc pumptherm.dbc --node-id-limit 16 '" + log.string() + "'");
  fs::remove(log);
  EXPECT_EQ(plain.exit_code, 0) << plain.out;
  EXPECT_NE(plain.out.find("0 frames decoded, 2 with IDs not in pumptherm.dbc"), std::string::npos)
      << plain.out;
  EXPECT_NE(plain.out.find("1 of the unknown frames are a message at CAN ID = DBC ID + node ID, "
                           "node IDs up to 3: the DBC's IDs are per pump (or per node); decode "
                           "them with --node-id-limit 4"),
            std::string::npos)
      << plain.out;
  EXPECT_NE(offset.out.find("1 frames decoded, 1 with IDs not in pumptherm.dbc"), std::string::npos)
      << offset.out;
  EXPECT_EQ(offset.out.find("of the unknown frames are a message"), std::string::npos)
      << offset.out;
}

// Every kind of frame that does not decode is counted, 29-bit ones too; a line without a
// timestamp has no time (null), not 0.
TEST(DbcCliTest, DecodeCountsEveryKindAndLeavesNoTimeNull) {
  const fs::path log = TempFile("kinds.log");
  std::ofstream(log) << "(1.000000) can0 12345678#00\n"                  // 29-bit, unknown
                     << "(1.100000) can0 20000080#0000000000000000\n"    // error frame
                     << "(1.200000) can0 103#R\n"                        // remote frame
                     << "  can0  100   [8]  00 00 00 00 00 00 00 00\n";  // screen, no time
  RunResult r = RunPumptherm("dbc decode --dbc pumptherm.dbc '" + log.string() + "'");
  EXPECT_EQ(r.exit_code, 0) << r.out;
  EXPECT_NE(r.out.find(R"({"time_s":null,"interface":"can0","can_id":"0x100","node":0,)"),
            std::string::npos)
      << r.out;
  EXPECT_NE(r.out.find("1 frames decoded, 1 with IDs not in pumptherm.dbc (0 11-bit, 1 29-bit), 0 "
                       "shorter than their message, 1 error and 1 remote frames not decoded"),
            std::string::npos)
      << r.out;
  r = RunPumptherm("dbc decode --format csv --dbc pumptherm.dbc '" + log.string() + "'");
  EXPECT_NE(r.out.find("\n,can0,0x100,0,PUMP_FAST_I,"), std::string::npos) << r.out;
  fs::remove(log);
}

// A named log that holds no frame, or is a directory, is no recording: exit 1 or 2, the file named.
TEST(DbcCliTest, DecodeOfAFileWithoutFramesOrADirectorySaysSo) {
  const fs::path log = TempFile("noframes.log");
  std::ofstream(log) << "hello\n# a comment\n";
  RunResult r = RunPumptherm("dbc decode --dbc pumptherm.dbc '" + log.string() + "'");
  EXPECT_EQ(r.exit_code, 1) << r.out;
  EXPECT_NE(r.out.find(log.string() + ": no CAN frame in 2 lines (1 not candump lines)"),
            std::string::npos)
      << r.out;
  fs::remove(log);
  const fs::path dir = TempFile("logdir");
  fs::create_directories(dir);
  r = RunPumptherm("dbc decode --dbc pumptherm.dbc '" + dir.string() + "'");
  EXPECT_EQ(r.exit_code, 2) << r.out;
  EXPECT_NE(r.out.find(dir.string() + ": is a directory, not a candump log"), std::string::npos)
      << r.out;
  r = RunPumptherm("dbc check '" + dir.string() + "'");
  EXPECT_EQ(r.exit_code, 2) << r.out;
  EXPECT_NE(r.out.find("is a directory, not a dbc file"), std::string::npos) << r.out;
  fs::remove_all(dir);
}

// A file that exists is a path, whatever the case of its extension (cantools' corpus has
// issue_168.DBC); a bare name that is no file here is the shipped file.
TEST(DbcCliTest, AFileWithAnUpperCaseExtensionIsAPath) {
  const fs::path dir = TempFile("upper");
  fs::create_directories(dir);
  fs::copy_file(test::PumpthermDbc(), dir / "Site.DBC", fs::copy_options::overwrite_existing);
  const std::string cd =
      "cd '" + dir.string() + "' && '" + PUMPTHERM_BIN + "' dbc check Site.DBC 2>&1";
  const test_files::CommandResult c = test_files::RunCommand(cd);
  EXPECT_EQ(c.exit_code, 0) << c.out;
  EXPECT_NE(c.out.find("Site.DBC: 12 messages"), std::string::npos) << c.out;
  fs::remove_all(dir);
}

/// PUMP_FAST_I of pump 3 as our encoder writes it (Id 12.345 A, Iq -0.5 A, 2199.11 rad/s, counter
/// 7).
CanFrame FastFrameOfPump3() {
  const Dbc dbc = ParseDbc(test::ReadFile(test::PumpthermDbc()), "pumptherm.dbc");
  const DbcMessage& fast = *dbc.FindMessage("PUMP_FAST_I");
  CanFrame f;
  f.id = fast.id + 3;
  f.len = 8;
  const std::vector<double> values = {12.345, -0.5, 2199.11, 7};
  EXPECT_EQ(MessageCodec(fast).Encode(values, std::span<std::uint8_t>(f.data.data(), 8)).status,
            CodecStatus::kOk);
  return f;
}

TEST(DbcCliTest, AnnotateEchoesEveryLineAsCantoolsDecodeDoes) {
  const CanFrame f = FastFrameOfPump3();
  CanFrame unknown = f;
  unknown.id = 0x6FF;
  const std::string frame_line = FormatCandumpLine(1700000000123456, "vcan0", f);
  const fs::path log = TempFile("annotate.log");
  std::ofstream(log) << "# recorded on the bench\n"
                     << frame_line << '\n'
                     << FormatCandumpLine(1700000000133456, "vcan0", unknown) << '\n'
                     << "(2.0) vcan0 10Z#00\n";
  RunResult r = RunPumptherm(
      "dbc decode --dbc pumptherm.dbc --node-id-limit 16 --format annotate -s", log.string());
  EXPECT_EQ(r.exit_code, 0) << r.out;
  // Lines that are not frames come back unchanged; a frame gets " ::" and its message.
  EXPECT_NE(r.out.find("# recorded on the bench\n" + frame_line +
                       " :: PUMP_FAST_I[node 3](Id_A: 12.345 A, Iq_A: -0.5 A, SpeedElec_rad_per_s: "
                       "2199.11 rad/s, "
                       "RollingCounter: 7)\n(1700000000.133456) vcan0 6FF#"),
            std::string::npos)
      << r.out;
  EXPECT_NE(r.out.find(" :: Unknown frame id 1791 (0x6ff)\n"), std::string::npos) << r.out;
  EXPECT_NE(r.out.find("\n(2.0) vcan0 10Z#00\n"), std::string::npos) << r.out;
  EXPECT_NE(
      r.out.find(
          "<stdin>:4:15: warning: expected a hexadecimal CAN ID; line passed through undecoded"),
      std::string::npos)
      << r.out;
  EXPECT_NE(
      r.out.find(
          "1 frames decoded, 1 with IDs not in pumptherm.dbc (1 11-bit, 0 29-bit), 0 shorter than "
          "their message, 0 error and 0 remote frames not decoded, 1 bad lines passed through "
          "undecoded"),
      std::string::npos)
      << r.out;

  // Without -s: one signal per indented line, as cantools decode's default.
  r = RunPumptherm("dbc decode --dbc pumptherm.dbc --node-id-limit 16 --format annotate '" +
                   log.string() + "'");
  EXPECT_NE(r.out.find(frame_line +
                       " ::\nPUMP_FAST_I[node 3](\n    Id_A: 12.345 A,\n    Iq_A: -0.5 A,\n"
                       "    SpeedElec_rad_per_s: 2199.11 rad/s,\n    RollingCounter: 7\n)\n"),
            std::string::npos)
      << r.out;
  fs::remove(log);
}

TEST(DbcCliTest, AnnotatePrintsValueLabelsAndLeavesOutUnselectedMuxSignals) {
  const Dbc dbc = ParseDbc(test::ReadFile(test::PumpthermDbc()), "pumptherm.dbc");
  const DbcMessage& alarm = *dbc.FindMessage("GW_ALARM");
  std::vector<double> values(alarm.signals.size(), 0.0);
  for (std::size_t i = 0; i < values.size(); ++i) {
    if (alarm.signals[i].name == "AlarmNode") values[i] = std::nan("");  // raw 15: VAL_ "none"
  }
  CanFrame f;
  f.id = alarm.id;
  f.len = static_cast<std::uint8_t>(alarm.size_bytes);
  ASSERT_EQ(
      MessageCodec(alarm).Encode(values, std::span<std::uint8_t>(f.data.data(), f.len)).status,
      CodecStatus::kOk);
  const fs::path log = TempFile("alarm.log");
  std::ofstream(log) << FormatCandumpLine(1, "can0", f) << '\n';
  RunResult r =
      RunPumptherm("dbc decode --dbc pumptherm.dbc --format annotate -s '" + log.string() + "'");
  EXPECT_NE(r.out.find("AlarmNode: none"), std::string::npos) << r.out;

  // Multiplexed signals: only those the multiplexer selects are printed (as cantools does).
  const fs::path mux_dbc = TempFile("mux.dbc");
  std::ofstream(mux_dbc)
      << "BO_ 100 MUXED: 2 X\n SG_ Sel M : 0|8@1+ (1,0) [0|1] \"\" X\n"
      << " SG_ A_V m0 : 8|8@1+ (1,0) [0|255] \"V\" X\n SG_ B_A m1 : 8|8@1+ (1,0) [0|255] \"A\" X\n";
  std::ofstream(log) << "(1.000000) can0 064#0105\n(2.000000) can0 064#0007\n";
  r = RunPumptherm("dbc decode --dbc '" + mux_dbc.string() + "' --format annotate -s '" +
                   log.string() + "'");
  EXPECT_NE(r.out.find("064#0105 :: MUXED(Sel: 1, B_A: 5 A)\n"), std::string::npos) << r.out;
  EXPECT_NE(r.out.find("064#0007 :: MUXED(Sel: 0, A_V: 7 V)\n"), std::string::npos) << r.out;
  fs::remove(mux_dbc);
  fs::remove(log);
}

TEST(DbcCliTest, AnnotateFromAPipeAnswersEachLineAtOnce) {
  // A live pipe (candump | pumptherm dbc decode): the answer to a line must come before stdin
  // closes, so the output is flushed line by line.
  int to_child[2], from_child[2];
  ASSERT_EQ(pipe(to_child), 0);
  ASSERT_EQ(pipe(from_child), 0);
  const pid_t pid = fork();
  ASSERT_GE(pid, 0);
  if (pid == 0) {
    dup2(to_child[0], 0);
    dup2(from_child[1], 1);
    close(to_child[1]);
    close(from_child[0]);
    execl(PUMPTHERM_BIN, PUMPTHERM_BIN, "dbc", "decode", "--dbc", "pumptherm.dbc",
          "--node-id-limit", "16", "--format", "annotate", "-s", static_cast<char*>(nullptr));
    _exit(127);
  }
  close(to_child[0]);
  close(from_child[1]);
  const std::string line = FormatCandumpLine(1700000000123456, "vcan0", FastFrameOfPump3()) + "\n";
  ASSERT_EQ(write(to_child[1], line.data(), line.size()), static_cast<ssize_t>(line.size()));
  // Read until the newline of the answer, with stdin still open; 10 s is a hang, not slowness.
  std::string out;
  pollfd pfd{from_child[0], POLLIN, 0};
  while (out.find('\n') == std::string::npos && poll(&pfd, 1, 10000) == 1) {
    char buf[512];
    const ssize_t n = read(from_child[0], buf, sizeof buf);
    if (n <= 0) break;
    out.append(buf, static_cast<std::size_t>(n));
  }
  close(to_child[1]);
  close(from_child[0]);
  int status = 0;
  waitpid(pid, &status, 0);
  EXPECT_NE(out.find(" :: PUMP_FAST_I[node 3](Id_A: 12.345 A"), std::string::npos)
      << "got: '" << out << "'";
  EXPECT_TRUE(WIFEXITED(status) && WEXITSTATUS(status) == 0);
}

}  // namespace
}  // namespace pumptherm::protocol
