#pragma once
/// The durable journal of an incident (issue 7): every accepted measurement row is committed
/// to SQLite (WAL, synchronous=FULL) before it is acknowledged; an exact repeat of a row already
/// journaled (e.g. an MQTT redelivery) is detected and dropped. Rows are stored in the mission
/// format's canonical CSV form per stream, in arrival order; the journal exports to a mission
/// directory. Survives a crash: reopening the file gives back every committed row.

#include <filesystem>
#include <functional>
#include <string>
#include <vector>

struct sqlite3;

namespace trailmark::server {

class Journal {
 public:
  /// Opens (creating when needed) the journal; throws std::runtime_error naming the file.
  explicit Journal(const std::filesystem::path& file);
  ~Journal();
  Journal(const Journal&) = delete;
  Journal& operator=(const Journal&) = delete;

  struct AppendResult {
    std::size_t accepted = 0, duplicates = 0;
  };
  /// Appends the rows of one stream (file name, e.g. "steps.csv") with its canonical header in
  /// one transaction; returns once committed.
  AppendResult Append(const std::string& stream, const std::string& header,
                      const std::vector<std::string>& rows);
  /// Rows of every stream in arrival order.
  void ForEach(const std::function<void(const std::string& stream, const std::string& header,
                                        const std::string& row)>& visit) const;
  std::size_t size() const;
  /// Writes every stream as `dir/<stream>` (header + rows), and `mission_json` as mission.json.
  void Export(const std::filesystem::path& dir, const std::filesystem::path& mission_json) const;

 private:
  void Exec(const char* sql) const;
  std::filesystem::path file_;
  sqlite3* db_ = nullptr;
};

}  // namespace trailmark::server
