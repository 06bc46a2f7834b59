// SPDX-License-Identifier: MIT
#pragma once
// A live server on loopback for the server tests (pipeline pdr on the office loop, token
// "s3cret-token", limits as its arguments) and a raw-socket client that sends exactly what a
// test wants (headers alone, endless chunks, a browser's Accept-Encoding).
#include <arpa/inet.h>
#include <netinet/in.h>
#include <poll.h>
#include <sys/socket.h>
#include <unistd.h>

#include <gtest/gtest.h>

#include <algorithm>
#include <chrono>
#include <cstdint>
#include <memory>
#include <string>
#include <vector>

#include "server/incident_server.h"
#include "test_util.h"
#include "trailmark/io/mission_io.h"
#include "trailmark/sim/scenarios.h"

namespace trailmark::server {

class Connection {
 public:
  /// `from`: the client's loopback address (Linux answers all of 127.0.0.0/8), so that one test
  /// can be several clients.
  explicit Connection(int port, const char* from = nullptr) : fd_(socket(AF_INET, SOCK_STREAM, 0)) {
    if (from != nullptr && fd_ >= 0) {
      sockaddr_in local{};
      local.sin_family = AF_INET;
      inet_pton(AF_INET, from, &local.sin_addr);
      if (bind(fd_, reinterpret_cast<sockaddr*>(&local), sizeof local) != 0) return;
    }
    sockaddr_in a{};
    a.sin_family = AF_INET;
    a.sin_port = htons(static_cast<std::uint16_t>(port));
    a.sin_addr.s_addr = htonl(INADDR_LOOPBACK);
    connected_ = fd_ >= 0 && connect(fd_, reinterpret_cast<sockaddr*>(&a), sizeof a) == 0;
  }
  ~Connection() {
    if (fd_ >= 0) close(fd_);
  }
  bool connected() const { return connected_; }
  /// False once the server has closed the connection (or reset it).
  bool Open() {
    pollfd p{fd_, POLLIN, 0};
    if (poll(&p, 1, 0) <= 0) return true;
    char c;
    return recv(fd_, &c, 1, MSG_PEEK | MSG_DONTWAIT) > 0;
  }
  /// False once the server has closed its side (it refused the rest).
  bool Send(const std::string& s) {
    return send(fd_, s.data(), s.size(), MSG_NOSIGNAL) == static_cast<ssize_t>(s.size());
  }
  /// What arrives within `timeout` (until the server closes or the head is complete).
  std::string Receive(std::chrono::milliseconds timeout) { return Read(timeout, true); }
  /// What arrives within `timeout` until the server closes: a whole reply of `Connection: close`.
  std::string ReceiveAll(std::chrono::milliseconds timeout) { return Read(timeout, false); }

 private:
  std::string Read(std::chrono::milliseconds timeout, bool head_only) {
    std::string got;
    const auto end = std::chrono::steady_clock::now() + timeout;
    while (std::chrono::steady_clock::now() < end &&
           !(head_only && got.find("\r\n\r\n") != std::string::npos)) {
      pollfd p{fd_, POLLIN, 0};
      const auto left = std::chrono::duration_cast<std::chrono::milliseconds>(
          end - std::chrono::steady_clock::now());
      if (poll(&p, 1, static_cast<int>(std::max<long>(left.count(), 0))) <= 0) break;
      char buf[65536];
      const ssize_t n = recv(fd_, buf, sizeof buf, 0);
      if (n <= 0) break;
      got.append(buf, static_cast<std::size_t>(n));
    }
    return got;
  }
  int fd_;
  bool connected_ = false;
};

class LiveServerFixture : public ::testing::Test {
 protected:
  void SetUp() override { Start(); }
  void Start(double header_deadline_s = 10.0, std::size_t per_address = 32,
             std::size_t threads = 64, double request_deadline_s = 60.0,
             std::size_t max_waiting = 256) {
    const SimulatedMission sim = SimulateScenario("office-loop", 1);
    WriteMissionDirectory(dir_.path() / "mission", sim.data, &sim.plan);
    ServerOptions o;
    o.live_dir = dir_.path() / "mission";
    o.journal_file = dir_.path() / "journal.db";
    o.pipeline = "pdr";
    o.port = 0;
    o.token = "s3cret-token";
    o.max_request_bytes = 64 * 1024;
    o.header_deadline_s = header_deadline_s;
    o.max_connections_per_address = per_address;
    o.http_threads = threads;
    o.request_deadline_s = request_deadline_s;
    o.max_waiting_connections = max_waiting;
    o.log = [](const std::string&) {};
    server_ = std::make_unique<IncidentServer>(sim.data.info, std::vector<Estimate>{}, o);
    server_->Start();
  }
  void Restart(double header_deadline_s, std::size_t per_address, std::size_t threads,
               double request_deadline_s = 60.0, std::size_t max_waiting = 256) {
    server_->Stop();
    server_.reset();
    dir_ = testing::TempDir();
    Start(header_deadline_s, per_address, threads, request_deadline_s, max_waiting);
  }
  void TearDown() override { server_->Stop(); }
  testing::TempDir dir_;
  std::unique_ptr<IncidentServer> server_;
};

}  // namespace trailmark::server
