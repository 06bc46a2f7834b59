// SPDX-License-Identifier: MIT
#pragma once
/// Streaming CSV for the mission format: one header line, '#' comment lines, columns in any
/// order, extra columns ignored, empty cell = unknown. Reads in fixed-size chunks, so memory
/// does not grow with the file; every problem is an InputError naming file and line.

#include <cstdio>
#include <memory>
#include <optional>
#include <string>
#include <string_view>
#include <vector>

namespace trailmark {

struct CsvReaderOptions {
  std::size_t max_line_bytes = 1 << 20;  ///< longer lines are rejected (not a CSV file)
  std::size_t chunk_bytes = 1 << 20;     ///< read buffer size
  /// Accept unnamed header cells (pandas index columns in third-party data); the mission
  /// format itself requires every column to be named.
  bool allow_unnamed_columns = false;
};

class CsvReader {
 public:
  using Options = CsvReaderOptions;

  /// Opens the file and reads its header. Throws InputError when the file is missing,
  /// unreadable, empty, binary, or its header is malformed.
  explicit CsvReader(std::string path, Options options = {});
  /// Reads `content` (a whole CSV document held in memory, e.g. an HTTP request body) under
  /// the name `name`, which errors use in place of a file path. `content` must outlive the reader.
  CsvReader(std::string name, std::string_view content, Options options);
  ~CsvReader();
  CsvReader(const CsvReader&) = delete;
  CsvReader& operator=(const CsvReader&) = delete;

  const std::string& path() const { return path_; }
  const std::vector<std::string>& header() const { return header_; }
  /// Index of a column, or -1 when the header does not have it.
  int Column(std::string_view name) const;
  /// Index of a column the caller needs; throws InputError naming it when absent.
  int RequireColumn(std::string_view name) const;

  /// Advances to the next data row (skipping comments and blank lines). False at end of file.
  bool Next();
  /// 1-based line number of the current row in the file.
  std::size_t line() const { return line_number_; }
  /// Bytes consumed so far (for progress reporting).
  std::size_t bytes_read() const { return bytes_consumed_; }
  std::size_t file_size() const { return file_size_; }

  std::string_view Field(int col) const { return fields_[static_cast<std::size_t>(col)]; }
  /// A finite number; throws on empty, non-numeric, NaN or infinite cells.
  double Double(int col) const;
  /// Empty when the cell is empty or the column is absent (col < 0); else as Double().
  std::optional<double> OptionalDouble(int col) const;
  /// A node id (non-empty, [A-Za-z0-9_.-]); throws otherwise.
  std::string_view NodeId(int col) const;
  /// Throws InputError at the current line.
  [[noreturn]] void Fail(const std::string& problem) const;

 private:
  void ReadHeader();
  void ReadHeaderOrClose();
  bool ReadLine(std::string_view* line);
  void SplitFields(std::string_view line);
  std::string ColumnName(int col) const;

  std::string path_;
  Options options_;
  std::FILE* file_ = nullptr;
  std::size_t file_size_ = 0;
  std::vector<char> buffer_;
  std::size_t begin_ = 0;  ///< unread data in buffer_[begin_, end_)
  std::size_t end_ = 0;
  bool eof_ = false;
  bool last_line_unterminated_ = false;
  std::size_t line_number_ = 0;
  std::size_t bytes_consumed_ = 0;
  std::vector<std::string> header_;
  std::vector<std::string_view> fields_;
};

/// Parses a finite decimal number (leading '+' and surrounding blanks allowed).
std::optional<double> ParseFiniteDouble(std::string_view text);

/// Buffered CSV writer. Numbers are written in shortest round-trip form; a non-finite number
/// is a programming error upstream and throws std::logic_error naming file and row.
class CsvWriter {
 public:
  CsvWriter(std::string path, const std::vector<std::string>& header);
  /// Writes each line (header first, without its newline) to `lines` instead of a file.
  CsvWriter(std::string name, const std::vector<std::string>& header,
            std::vector<std::string>* lines);
  ~CsvWriter();
  CsvWriter(const CsvWriter&) = delete;
  CsvWriter& operator=(const CsvWriter&) = delete;

  CsvWriter& Add(double value);
  CsvWriter& Add(std::optional<double> value);  ///< empty cell when unknown
  CsvWriter& Add(std::string_view text);
  void EndRow();
  /// Flushes and closes; throws std::runtime_error when the disk refused the data.
  void Close();
  const std::string& path() const { return path_; }
  std::size_t rows() const { return rows_; }

 private:
  void Separator();
  std::string path_;
  std::FILE* file_ = nullptr;
  std::vector<std::string>* lines_ = nullptr;
  std::string row_;
  std::size_t columns_ = 0;
  std::size_t cells_in_row_ = 0;
  std::size_t rows_ = 0;
};

}  // namespace trailmark
