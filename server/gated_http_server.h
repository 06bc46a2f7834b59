// SPDX-License-Identifier: MIT
#pragma once
/// cpp-httplib's server with a gate on each connection (issue 30, item 2): a cap on the
/// connections one client address holds at once, and a deadline for each request's line and
/// headers. cpp-httplib 0.11 (Debian 12) reads headers with a per-read timeout only, so a client
/// sending a byte every few seconds held a worker thread for as long as it liked, and 100 such
/// clients held every thread (health probes waited 30 s). This class takes over the library's
/// per-connection loop (`process_and_close_socket`, the keep-alive loop around the library's own
/// `process_request`) with a socket stream of its own that enforces the deadline; everything
/// else — parsing, routing, responses — is the library's. With TLS, the handshake is ours as
/// well (OpenSSL, on the library's context), within the header deadline.

#include <httplib.h>

#include <condition_variable>
#include <deque>
#include <functional>
#include <mutex>
#include <string>
#include <thread>
#include <utility>
#include <vector>

#include "server/connection_limits.h"

namespace trailmark::server {

/// cpp-httplib's thread pool with a bound on the connections waiting for a worker: beyond
/// `max_waiting` a connection is refused at once (503) by the accepting thread.
class BoundedThreadPool : public httplib::TaskQueue {
 public:
  BoundedThreadPool(std::size_t threads, std::size_t max_waiting);
  ~BoundedThreadPool() override;
  void enqueue(std::function<void()> fn) override;
  void shutdown() override;

 private:
  void Work();
  std::size_t max_waiting_;
  std::vector<std::thread> threads_;
  std::deque<std::function<void()>> jobs_;
  bool shutdown_ = false;
  std::condition_variable cond_;
  std::mutex mutex_;
};

/// What the gated servers share: the limits, the counts, the log.
class GateCore {
 public:
  GateCore(ConnectionLimits limits, std::function<void(const std::string&)> log);
  const GateStats& gate_stats() const { return stats_; }
  /// The pool to give the server (`new_task_queue`): `threads` workers, the gate's waiting cap.
  httplib::TaskQueue* NewTaskQueue(std::size_t threads) const;

 protected:
  /// `log` receives a line for the first event of each kind and then at every power of ten
  /// (a flood of strangers does not flood the log).
  void Note(std::atomic<std::size_t>& counter, const std::string& what);
  ConnectionLimits limits_;
  std::function<void(const std::string&)> log_;
  AddressCounter addresses_;
  GateStats stats_;
};

/// `Base` (httplib::Server, or httplib::SSLServer: the handshake is ours too, within the
/// header deadline) with the gate on each connection.
template <class Base>
class Gated final : public Base, public GateCore {
 public:
  template <class... BaseArgs>
  Gated(ConnectionLimits limits, std::function<void(const std::string&)> log,
        BaseArgs&&... base_args)
      : Base(std::forward<BaseArgs>(base_args)...), GateCore(limits, std::move(log)) {}

 private:
  bool process_and_close_socket(socket_t sock) override;
};

using GatedHttpServer = Gated<httplib::Server>;
using GatedHttpsServer = Gated<httplib::SSLServer>;

extern template class Gated<httplib::Server>;
extern template class Gated<httplib::SSLServer>;

}  // namespace trailmark::server
