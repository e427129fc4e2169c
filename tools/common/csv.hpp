#pragma once
/// Numeric CSV tables for the tools (docs/architecture.md, "Files people write or read"): a header
/// row, then one row of numbers per line; units in the column names (`time_s`, `iq_A`,
/// `frame_degC`).
///
/// Reading checks every cell as it is asked for and throws `CsvError` naming the file, the row
/// (1-based line number in the file) and the column name. Nothing is silently converted.

#include <cstddef>
#include <cstdio>
#include <optional>
#include <span>
#include <stdexcept>
#include <string>
#include <string_view>
#include <vector>

namespace pumptherm::tools {

/// Bad CSV input: the message names file, row and column. Subcommands turn it into exit code 2.
class CsvError : public std::runtime_error {
 public:
  using std::runtime_error::runtime_error;
};

/// A parsed CSV file: column names and rows of cells, all text until a column is asked for.
class CsvTable {
 public:
  /// Parses `text`; `source` names it in errors (a path, or "<stdin>").
  /// Throws CsvError: empty text, no header, duplicate column name, a row with a different
  /// number of cells than the header.
  static CsvTable Parse(std::string_view text, std::string source);

  /// Reads and parses the file at `path` ("-" reads standard input).
  /// Throws CsvError when it cannot be read (with errno's text) or does not parse.
  static CsvTable Read(const std::string& path);

  const std::string& source() const { return source_; }
  const std::vector<std::string>& columns() const { return columns_; }
  std::size_t rows() const { return rows_.size(); }
  /// Whether the column is there. A temperature column is found under either unit suffix,
  /// `_degC` or `_C` (`frame_degC` finds `frame_C` and the reverse): the same quantity.
  bool Has(std::string_view column) const { return Index(column).has_value(); }

  /// Every value of a required numeric column. Throws CsvError when the column is missing, or a
  /// cell is empty, not a number, NaN or infinite (naming the row and column).
  std::vector<double> Column(std::string_view column) const;

  /// Like Column(), but an empty or "nan" cell gives NaN ("not measured"); still rejects text
  /// that is not a number and infinities.
  std::vector<double> ColumnAllowingNaN(std::string_view column) const;

  /// Every cell of a column as written (trimmed), e.g. a column of words. Throws CsvError when
  /// the column is missing.
  std::vector<std::string> Text(std::string_view column) const;

  /// A column of codes written as numbers or as words (docs/daemon.md, "Names": CSV files write
  /// codes as words): a cell equal to `words[k]` gives k, a number gives itself, an empty or
  /// "nan" cell gives NaN. Throws CsvError naming the row and column for any other text.
  std::vector<double> Codes(std::string_view column, std::span<const std::string_view> words) const;

  /// The `time_s` column (or `column`), checked to be strictly increasing; throws CsvError
  /// naming the first row where time does not advance.
  std::vector<double> Time(std::string_view column = "time_s") const;

  /// File line number (1-based) of data row `row` (0-based), for error messages.
  std::size_t LineOf(std::size_t row) const { return lines_[row]; }

  /// One line per header column read under its current name because the file has the old one
  /// (`winding_res_C` -> `winding_resistance_degC`); Parse also prints each as a warning on stderr.
  const std::vector<std::string>& deprecations() const { return deprecations_; }

 private:
  void RenameDeprecatedColumns(std::size_t header_line);
  std::optional<std::size_t> Index(std::string_view column) const;
  std::vector<double> Numbers(std::string_view column, bool allow_nan) const;

  std::string source_;
  std::vector<std::string> columns_;
  std::vector<std::vector<std::string>> rows_;
  std::vector<std::size_t> lines_;
  std::vector<std::string> deprecations_;
};

/// Writes a CSV file: header, then rows of numbers with `%.9g`-style shortest round-trip text.
class CsvWriter {
 public:
  /// Opens `path` for writing ("-" is standard output). Throws std::system_error on failure.
  CsvWriter(const std::string& path, std::vector<std::string> columns);
  ~CsvWriter();
  CsvWriter(const CsvWriter&) = delete;
  CsvWriter& operator=(const CsvWriter&) = delete;

  /// Appends one row; `values.size()` must equal the number of columns (else std::logic_error).
  void Row(const std::vector<double>& values);
  /// Appends one row of `values` followed by the text cells `text` (written as given: no comma,
  /// quote or newline in them); together they must fill the columns (else std::logic_error).
  void Row(const std::vector<double>& values, const std::vector<std::string>& text);
  /// Flushes and closes; throws std::system_error when the data could not be written.
  void Close();

 private:
  std::FILE* file_ = nullptr;
  bool owned_ = false;
  std::string path_;
  std::size_t columns_ = 0;
  std::string line_;
};

}  // namespace pumptherm::tools
