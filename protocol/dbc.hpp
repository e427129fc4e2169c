#pragma once
/// A reader for Vector's DBC format (the CAN database text format of CANdb++).
///
/// Supported: `VERSION`, `BU_`, `BO_`, `SG_` (Intel `@1` and Motorola `@0` byte order, signed and
/// unsigned, factor, offset, min, max, unit, receivers), multiplexing (`M`, `mN`, and extended
/// multiplexing `mNM` with `SG_MUL_VAL_`), `VAL_` and `VAL_TABLE_`, `CM_`, `BA_DEF_`,
/// `BA_DEF_DEF_` and `BA_` (including `GenMsgCycleTime`), `SIG_VALTYPE_` (IEEE float and double
/// signals), 29-bit IDs (bit 31 of the DBC ID) and CAN FD lengths up to 64 bytes. Other sections
/// (`NS_`, `BS_`, `EV_`, `SIG_GROUP_`, `BO_TX_BU_`, ...) are skipped.
///
/// Pure parsing: the caller hands in the text and a name for messages. A locally malformed
/// statement is skipped and collected in `Dbc::problems` with its line and column, as are
/// oddities that do not stop decoding (a signal reaching past the declared length, which then
/// decodes as not available; a reference to an unknown signal in `VAL_`). Errors that leave
/// nothing to load throw `DbcError` naming file, line and column and what was expected.
///
/// Project convention (docs/protocol.md): a signal attribute `GenSigSNA` holds the raw value
/// that means "not available"; the codec decodes it to NaN and encodes NaN to it.
///
/// Long names: Vector's tools write names of at most 32 characters in the statements and the
/// whole name as a STRING attribute (`SystemSignalLongSymbol`, `SystemMessageLongSymbol`,
/// `SystemNodeLongSymbol`); as in cantools and canmatrix, the long name is the name (of the
/// signal, message, node, and of transmitters and receivers), and the attribute is dropped.
/// Statements in the file refer to the short names. `SystemEnvVarLongSymbol` names environment
/// variables, which this reader skips.

#include <cstdint>
#include <map>
#include <optional>
#include <stdexcept>
#include <string>
#include <string_view>
#include <variant>
#include <vector>

namespace pumptherm::protocol {

/// Bit numbering of a signal: `@1` Intel (little endian, start bit = least significant bit),
/// `@0` Motorola (big endian, start bit = most significant bit in the DBC's sawtooth numbering).
enum class ByteOrder { kLittleEndian, kBigEndian };

/// How the raw bits are read (`SIG_VALTYPE_`): an integer, or an IEEE 754 float (32 bits) or
/// double (64 bits).
enum class SignalValueType { kInteger, kFloat32, kFloat64 };

/// An inclusive range of multiplexer raw values (`SG_MUL_VAL_`, or `mN` giving N..N).
struct MuxRange {
  std::uint64_t low = 0;
  std::uint64_t high = 0;
};

/// An attribute value: a number (INT, HEX, FLOAT, and ENUM as its index) or text (STRING, and
/// ENUM as its label).
using DbcAttributeValue = std::variant<double, std::string>;

/// Attributes of one object, by name.
using DbcAttributes = std::map<std::string, DbcAttributeValue, std::less<>>;

/// One signal (`SG_`).
struct DbcSignal {
  std::string name;
  std::uint32_t start_bit = 0;  ///< as written in the file (see ByteOrder)
  std::uint32_t length_bits = 0;
  ByteOrder byte_order = ByteOrder::kLittleEndian;
  bool is_signed = false;
  SignalValueType value_type = SignalValueType::kInteger;
  double factor = 1.0;  ///< physical = raw * factor + offset
  double offset = 0.0;
  double minimum = 0.0;  ///< declared physical range (both 0 often means "not given")
  double maximum = 0.0;
  std::string unit;
  std::vector<std::string> receivers;

  bool is_multiplexer = false;  ///< `M`, or the `M` of an extended `mNM`
  /// Name of the multiplexer switch this signal depends on; empty if always present.
  std::string multiplexer_switch;
  /// Switch raw values for which this signal is present (from `mN` or `SG_MUL_VAL_`).
  std::vector<MuxRange> multiplexer_ranges;

  std::string comment;
  std::map<std::int64_t, std::string> value_descriptions;  ///< `VAL_`, raw value -> label
  DbcAttributes attributes;
  /// Raw value meaning "not available" (attribute `GenSigSNA`), if declared.
  std::optional<std::int64_t> not_available_raw;

  int line = 0;    ///< line of the `SG_` in the file, for messages
  int column = 0;  ///< column of the `SG_`
};

/// One message (`BO_`).
struct DbcMessage {
  std::uint32_t id = 0;  ///< 11 or 29 bits, without the extended flag
  bool extended = false;
  std::string name;
  std::uint32_t size_bytes = 0;  ///< declared length (DLC as bytes), up to 64 for CAN FD
  std::string transmitter;
  std::vector<DbcSignal> signals;
  std::string comment;
  DbcAttributes attributes;
  /// `GenMsgCycleTime` in milliseconds (the message's value, else the attribute default).
  std::optional<double> cycle_time_ms;
  int line = 0;

  /// Index into `signals` of the signal called `name`, or -1.
  int FindSignal(std::string_view signal_name) const noexcept;
};

/// Declaration of an attribute (`BA_DEF_`), with its default (`BA_DEF_DEF_`).
struct DbcAttributeDefinition {
  enum class Object { kNetwork, kNode, kMessage, kSignal, kEnvironment };
  enum class Type { kInt, kHex, kFloat, kString, kEnum };
  std::string name;
  Object object = Object::kNetwork;
  Type type = Type::kInt;
  double minimum = 0.0;
  double maximum = 0.0;
  std::vector<std::string> enum_values;
  std::optional<DbcAttributeValue> default_value;
};

/// Something in the file that does not stop loading but a person should look at.
struct DbcProblem {
  int line = 0;
  int column = 0;  ///< 1-based; 0 if the problem concerns a whole line
  std::string message;
};

/// A whole DBC file.
struct Dbc {
  std::string file_name;
  std::string version;
  std::vector<std::string> nodes;
  std::vector<DbcMessage> messages;
  std::map<std::string, std::map<std::int64_t, std::string>, std::less<>> value_tables;
  std::vector<DbcAttributeDefinition> attribute_definitions;
  DbcAttributes network_attributes;
  /// Attributes (`BA_ "..." BU_ node`) and comments (`CM_ BU_`) of the nodes, by node name.
  std::map<std::string, DbcAttributes, std::less<>> node_attributes;
  std::map<std::string, std::string, std::less<>> node_comments;
  std::string comment;
  std::vector<DbcProblem> problems;

  /// The message called `name`, or nullptr.
  const DbcMessage* FindMessage(std::string_view name) const noexcept;
  /// The message with this CAN ID (11 or 29 bits) and frame format, or nullptr.
  const DbcMessage* FindMessage(std::uint32_t id, bool extended) const noexcept;
};

/// Bytes a signal touches: one past the highest byte index it occupies (may exceed 64 for a
/// signal that leaves a CAN FD frame, which ParseDbc rejects).
std::uint32_t SignalEndByte(const DbcSignal& signal) noexcept;

/// A DBC syntax or consistency error, with where it was found.
class DbcError : public std::runtime_error {
 public:
  DbcError(std::string file, int line, int column, const std::string& what);
  const std::string& file() const noexcept { return file_; }
  int line() const noexcept { return line_; }      ///< 1-based
  int column() const noexcept { return column_; }  ///< 1-based
  /// What went wrong, without the file:line:column prefix.
  const std::string& detail() const noexcept { return detail_; }

 private:
  std::string file_;
  std::string detail_;
  int line_;
  int column_;
};

/// Parses DBC text. `file_name` only labels errors and problems.
///
/// A locally malformed statement (a syntax error, a message ID above 29 bits, a duplicate
/// message ID or signal name, a signal outside 64 bytes, a `CM_` missing its ';') is a problem
/// naming its line and column; that statement is skipped (a `BO_` with its signals, or one
/// `SG_`) and the rest of the file loads. A `GenSigSNA` that is not an integer raw value
/// fitting the signal is a problem and is ignored.
/// Throws DbcError (file, line, column, what was expected) on an unterminated string, on a
/// file where statements were skipped and no message loads, and on whole-file inconsistencies:
/// a multiplexed signal without a unique multiplexer, an `SG_MUL_VAL_` naming an unknown
/// signal, a multiplexer cycle.
Dbc ParseDbc(std::string_view text, std::string_view file_name);

}  // namespace pumptherm::protocol
