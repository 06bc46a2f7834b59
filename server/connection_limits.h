// SPDX-License-Identifier: MIT
#pragma once
/// What the incident server's connection gate enforces (server/gated_http_server.h), without
/// the HTTP library: usable and testable on its own.

#include <atomic>
#include <cstddef>
#include <map>
#include <mutex>
#include <string>

namespace trailmark::server {

struct ConnectionLimits {
  /// A request's line and headers must all arrive within this (s) of its first byte.
  double header_deadline_s = 10.0;
  /// ... and the whole request, its body too, within this (s): 1 MiB in 60 s is 17 kB/s. Not
  /// the response (an event stream lasts the incident).
  double request_deadline_s = 60.0;
  /// Connections accepted while every worker is busy wait for one; beyond this many waiting,
  /// a connection is answered 503 and closed at once.
  std::size_t max_waiting = 256;
  /// Connections one client address may hold at once (0: no cap); more are answered 503 and
  /// closed. Below the server's worker threads, so that one address cannot take them all.
  std::size_t max_per_address = 32;
  bool IsValid(std::string* why) const;
};

/// Counts of what the gate refused.
struct GateStats {
  std::atomic<std::size_t> refused_per_address{0};  ///< connections over an address's cap
  std::atomic<std::size_t> header_deadlines{0};     ///< requests whose headers came too slowly
  std::atomic<std::size_t> request_deadlines{0};    ///< requests whose bodies came too slowly
  std::atomic<std::size_t> refused_waiting{0};      ///< connections beyond max_waiting
  std::atomic<std::size_t> handshakes_failed{0};    ///< TLS: none within the header deadline
};

/// Open connections by client address (thread-safe).
class AddressCounter {
 public:
  explicit AddressCounter(std::size_t cap) : cap_(cap) {}
  /// Takes a place for `address`; false (nothing taken) when it holds `cap` already.
  bool Admit(const std::string& address);
  void Release(const std::string& address);
  std::size_t Open(const std::string& address) const;

 private:
  std::size_t cap_;
  mutable std::mutex mutex_;
  std::map<std::string, std::size_t> open_;
};

}  // namespace trailmark::server
