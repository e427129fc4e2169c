#pragma once
/// One pump's drive telemetry from a candump recording, as the tools' CSV convention
/// (time_s, id_A, iq_A, ud_V, uq_V, speed_rpm, frame_degC, ambient_degC), so that `identify`,
/// `estimate` and `telemetry` read a recording directly. The frames are decoded with a DBC and
/// the signal mapping the daemon uses; a current frame and a voltage frame make one row when
/// they are paired as the daemon pairs them (same rolling counter, at most 50 ms apart); the
/// frame and ambient temperatures are the latest status frame's, held, and rows start at the
/// first status frame when the mapping has those temperatures.

#include <CLI/CLI.hpp>
#include <cstdint>
#include <string>

namespace pumptherm::tools {

struct RecordingSource {
  std::string log;                    ///< candump log ('-': standard input)
  std::uint32_t node_id = 1;          ///< the pump's node ID (CAN ID = DBC ID + node ID)
  std::string interface;              ///< only frames of this interface ("": any)
  std::string dbc = "pumptherm.dbc";  ///< path or shipped name
  std::string mapping = "mapping_pumptherm.toml";  ///< path or shipped name
  std::string motor = "han2019-tmp";               ///< preset or file: pole pairs for the speed
};

struct RecordingCounts {
  std::uint64_t lines = 0;
  std::uint64_t bad_lines = 0;      ///< not candump lines: skipped, the first few warned
  std::uint64_t untimed_lines = 0;  ///< screen-format lines without a timestamp: skipped, warned
  std::uint64_t frames = 0;         ///< frames of this pump's mapped input messages
  std::uint64_t undecodable = 0;    ///< of those, too short for their message
  std::uint64_t unpaired = 0;       ///< current or voltage frames without a partner
  std::uint64_t rows = 0;
  std::int64_t first_us = -1;  ///< the first row's time (time_s = 0), Unix microseconds
};

/// Adds --log, --node-id, --interface, --dbc, --mapping to `app` (the motor comes from the
/// subcommand's own --motor where it has one).
void AddRecordingOptions(CLI::App& app, RecordingSource& source);

/// The rows as CSV text with a header; the log in any format ParseCandumpLine reads. Warnings
/// about bad lines and lines without a timestamp go to stderr with file:line.
/// Throws InputError for an unreadable log, DBC, mapping or motor file, a node ID at or above the
/// mapping's limit, or a recording with no paired row for the pump.
std::string RecordingToCsv(const RecordingSource& source, RecordingCounts* counts);

}  // namespace pumptherm::tools
