#pragma once
/// The durable journal of an incident (issue 7): every accepted measurement row is committed
/// to SQLite (WAL, synchronous=FULL) before it is acknowledged; an exact repeat of a row already
/// journaled (e.g. an MQTT redelivery) is detected and dropped; a row older than the last one
/// accepted from its node in its stream is refused (a device's rows come in time order, as the
/// mission format requires). Rows are stored in the mission format's canonical CSV form with
/// their time and node; the journal exports to a mission directory (each stream in time order).
/// Several requests commit together in one transaction (group commit, `AppendGroup`): one disk
/// flush for all of them. Survives a crash: reopening the file gives back every committed row.

#include <filesystem>
#include <functional>
#include <map>
#include <mutex>
#include <string>
#include <utility>
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

  /// The rows of one request: one stream (file name, e.g. "steps.csv") with its canonical
  /// header; per row its canonical text, time, node (RowNode) and line in the request body.
  struct Batch {
    std::string stream, header;
    std::vector<std::string> rows;
    std::vector<double> t;
    std::vector<std::string> node;
    std::vector<std::size_t> lines;
  };
  struct AppendResult {
    std::size_t accepted = 0, duplicates = 0;
    /// Non-empty when the batch was refused as a whole (a row out of time order): names the
    /// line, node and times. Nothing of a refused batch is journaled.
    std::string error;
    std::vector<bool> fresh;  ///< per row: newly journaled (false: a duplicate)
  };
  /// Appends the batches in one transaction; returns once committed (per batch, in order).
  std::vector<AppendResult> AppendGroup(const std::vector<const Batch*>& batches);
  AppendResult Append(const Batch& batch) { return AppendGroup({&batch}).front(); }

  /// Rows of every stream in arrival order.
  void ForEach(const std::function<void(const std::string& stream, const std::string& header,
                                        const std::string& row)>& visit) const;
  std::size_t size() const;
  std::size_t commits() const {
    std::lock_guard<std::mutex> lock(mutex_);
    return commits_;
  }
  /// Writes every stream as `dir/<stream>` (header + rows in time order, arrival order among
  /// equal times), and `mission_json` as mission.json.
  void Export(const std::filesystem::path& dir, const std::filesystem::path& mission_json) const;

 private:
  void Exec(const char* sql) const;
  std::filesystem::path file_;
  sqlite3* db_ = nullptr;
  mutable std::mutex mutex_;  ///< one connection, used by the committer and the exporters
  /// Time of the last accepted row per (stream, node).
  std::map<std::pair<std::string, std::string>, double> last_t_;
  std::size_t commits_ = 0;
};

}  // namespace trailmark::server
