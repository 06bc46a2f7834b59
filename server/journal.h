// SPDX-License-Identifier: MIT
#pragma once
/// The durable journal of an incident (issue 7): every accepted measurement row is committed
/// to SQLite (WAL, synchronous=FULL) before it is acknowledged; an exact repeat of a row already
/// journaled (e.g. an MQTT redelivery) is detected and dropped; a row older than the last one
/// accepted from its node in its stream is refused (a device's rows come in time order, as the
/// mission format requires). Rows are stored in the mission format's canonical CSV form with
/// their time and node; the journal exports to a mission directory (each stream in time order).
/// Several requests commit together in one transaction (group commit, `AppendGroup`): one disk
/// flush for all of them. Survives a crash: reopening the file gives back every committed row.
///
/// Never reports less or other than it holds (issue 30): every read ends on SQLITE_DONE or
/// throws; opening runs `PRAGMA quick_check`; every commit also counts itself (commits and rows,
/// in the same transaction) and, once committed and before it is acknowledged, writes that count
/// to a high-water mark beside the journal (`FILE.acked`, fsynced): a journal that holds fewer
/// commits than were acknowledged (a lost or damaged write-ahead log, a file rolled back, a
/// zero-byte file) is refused at open with the reason. `Open::kSalvage` opens such a journal
/// read-only to export what is still readable.

#include <filesystem>
#include <functional>
#include <map>
#include <memory>
#include <mutex>
#include <string>
#include <utility>
#include <vector>

struct sqlite3;

namespace trailmark::server {

class Journal {
 public:
  enum class Open {
    kNormal,   ///< create when absent; refuse a journal that cannot be trusted
    kSalvage,  ///< read what is readable of a damaged one (no writes, no refusal)
  };
  /// Opens (creating when needed) the journal; throws std::runtime_error naming the file and
  /// the reason when it cannot be opened or trusted (and how to salvage it).
  explicit Journal(const std::filesystem::path& file, Open mode = Open::kNormal);
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

  /// Rows of every stream in arrival order. Throws std::runtime_error at a row it cannot read.
  void ForEach(const std::function<void(const std::string& stream, const std::string& header,
                                        const std::string& row)>& visit) const;
  std::size_t size() const;
  /// What a salvage open found wrong (empty when the journal is sound).
  const std::vector<std::string>& problems() const { return problems_; }
  std::size_t commits() const {
    std::lock_guard<std::mutex> lock(mutex_);
    return commits_;
  }
  /// Writes every stream as `dir/<stream>` (header + rows in time order, arrival order among
  /// equal times), and `mission_json` as mission.json; returns the rows written. Throws at the
  /// first row it cannot read — except when salvaging, where it writes what it could read and
  /// notes the error in problems().
  std::size_t Export(const std::filesystem::path& dir,
                     const std::filesystem::path& mission_json);

 private:
  void Exec(const char* sql) const;
  /// The commits and rows the journal's meta table counts.
  std::pair<long long, long long> Counted() const;
  void WriteHighWaterMark(long long commits, long long rows);
  Open mode_;
  std::vector<std::string> problems_;
  std::filesystem::path acked_file_;
  int acked_fd_ = -1;
  long long counted_commits_ = 0, counted_rows_ = 0;
  std::filesystem::path file_;
  sqlite3* db_ = nullptr;
  mutable std::mutex mutex_;  ///< one connection, used by the committer and the exporters
  /// Time of the last accepted row per (stream, node).
  std::map<std::pair<std::string, std::string>, double> last_t_;
  /// The latest accepted time of any (stream, node); -inf when none (a new device's check).
  double LatestTime() const;
  std::size_t commits_ = 0;
  struct Prepared;  ///< the append's statements, prepared once (normal mode)
  std::unique_ptr<Prepared> prepared_;
};

}  // namespace trailmark::server
