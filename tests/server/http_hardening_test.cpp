// SPDX-License-Identifier: MIT
// Strangers cannot stall or bloat the live server (issue 30, item 2): the token is checked on
// the headers before any body is read, the size limit holds for chunked bodies, and the token
// comparison does not depend on where the first wrong byte is. Raw sockets on loopback, so the
// test sends exactly what a hostile client would (headers alone, endless chunks).
#include <arpa/inet.h>
#include <netinet/in.h>
#include <poll.h>
#include <sys/socket.h>
#include <unistd.h>

#include <gtest/gtest.h>

#include <chrono>
#include <string>

#include "server/incident_server.h"
#include "test_util.h"
#include "trailmark/io/mission_io.h"
#include "trailmark/sim/scenarios.h"

namespace trailmark::server {
namespace {

using trailmark::testing::TempDir;

class Connection {
 public:
  explicit Connection(int port) : fd_(socket(AF_INET, SOCK_STREAM, 0)) {
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
  /// False once the server has closed its side (it refused the rest).
  bool Send(const std::string& s) {
    return send(fd_, s.data(), s.size(), MSG_NOSIGNAL) == static_cast<ssize_t>(s.size());
  }
  /// What arrives within `timeout` (until the server closes or the status line is complete).
  std::string Receive(std::chrono::milliseconds timeout) {
    std::string got;
    const auto end = std::chrono::steady_clock::now() + timeout;
    while (std::chrono::steady_clock::now() < end && got.find("\r\n\r\n") == std::string::npos) {
      pollfd p{fd_, POLLIN, 0};
      const auto left = std::chrono::duration_cast<std::chrono::milliseconds>(
          end - std::chrono::steady_clock::now());
      if (poll(&p, 1, static_cast<int>(std::max<long>(left.count(), 0))) <= 0) break;
      char buf[4096];
      const ssize_t n = recv(fd_, buf, sizeof buf, 0);
      if (n <= 0) break;
      got.append(buf, static_cast<std::size_t>(n));
    }
    return got;
  }

 private:
  int fd_;
  bool connected_ = false;
};

class LiveServerFixture : public ::testing::Test {
 protected:
  void SetUp() override {
    const SimulatedMission sim = SimulateScenario("office-loop", 1);
    WriteMissionDirectory(dir_.path() / "mission", sim.data, &sim.plan);
    ServerOptions o;
    o.live_dir = dir_.path() / "mission";
    o.journal_file = dir_.path() / "journal.db";
    o.pipeline = "pdr";
    o.port = 0;
    o.token = "s3cret-token";
    o.max_request_bytes = 64 * 1024;
    o.log = [](const std::string&) {};
    server_ = std::make_unique<IncidentServer>(sim.data.info, std::vector<Estimate>{}, o);
    server_->Start();
  }
  void TearDown() override { server_->Stop(); }
  TempDir dir_;
  std::unique_ptr<IncidentServer> server_;
};

std::string ChunkedHeaders(const std::string& token) {
  return "POST /api/ingest/steps.csv HTTP/1.1\r\nHost: 127.0.0.1\r\n" +
         (token.empty() ? std::string() : "Authorization: Bearer " + token + "\r\n") +
         "Content-Type: text/csv\r\nTransfer-Encoding: chunked\r\n\r\n";
}

TEST_F(LiveServerFixture, AStrangerIsRefusedOnItsHeadersBeforeItsBodyIsRead) {
  // Headers only: the body never comes. The 401 must not wait for it (the read timeout is 5 s).
  Connection c(server_->port());
  ASSERT_TRUE(c.connected());
  ASSERT_TRUE(c.Send(ChunkedHeaders("")));
  const auto t0 = std::chrono::steady_clock::now();
  const std::string reply = c.Receive(std::chrono::milliseconds(3000));
  EXPECT_LT(std::chrono::steady_clock::now() - t0, std::chrono::milliseconds(2500));
  EXPECT_NE(reply.find(" 401 "), std::string::npos) << reply;
  // With a wrong token too, and a Content-Length body of 10 MB announced.
  Connection d(server_->port());
  ASSERT_TRUE(d.Send("POST /api/ingest/steps.csv HTTP/1.1\r\nHost: x\r\nAuthorization: Bearer "
                     "s3cret-tokem\r\nContent-Length: 10000000\r\n\r\n"));
  EXPECT_NE(d.Receive(std::chrono::milliseconds(3000)).find(" 401 "), std::string::npos);
}

TEST_F(LiveServerFixture, AChunkedBodyBeyondTheLimitIsRefused) {
  // 64 KiB allowed: 1 MiB in 8 KiB chunks is refused with 413 and nothing is ingested.
  Connection c(server_->port());
  ASSERT_TRUE(c.connected());
  ASSERT_TRUE(c.Send(ChunkedHeaders("s3cret-token")));
  std::string chunk = "t0,t1,agent,dx,dy\n";
  while (chunk.size() < 8192) chunk += "0,1,ff1,0.7,0\n";
  std::size_t sent = 0;
  char size_hex[32];
  std::snprintf(size_hex, sizeof size_hex, "%zx\r\n", chunk.size());
  while (sent < (1u << 20) && c.Send(size_hex + chunk + "\r\n")) sent += chunk.size();
  c.Send("0\r\n\r\n");
  const std::string reply = c.Receive(std::chrono::milliseconds(5000));
  EXPECT_NE(reply.find(" 413 "), std::string::npos) << reply.substr(0, 200);
  EXPECT_EQ(server_->stats().ingested_rows.load(), 0u);
}

TEST_F(LiveServerFixture, APathOutOfTheDashboardIsNotServed) {
  // Path traversal (issue 30's must-hold): raw, so no client normalizes the dots away. The
  // dashboard's files are compiled in (no file system behind the routes): a regression test for
  // whoever mounts a directory later.
  for (const char* path : {"/../../../../etc/passwd", "/%2e%2e/%2e%2e/%2e%2e/etc/passwd",
                           "/assets/../../../../etc/passwd"}) {
    Connection c(server_->port());
    ASSERT_TRUE(c.connected());
    ASSERT_TRUE(c.Send(std::string("GET ") + path + " HTTP/1.1\r\nHost: x\r\n\r\n"));
    const std::string reply = c.Receive(std::chrono::milliseconds(3000));
    EXPECT_TRUE(reply.find(" 404 ") != std::string::npos || reply.find(" 400 ") != std::string::npos)
        << path << ": " << reply.substr(0, 120);
  }
}

TEST(SameSecret, ComparesWholeSecretsOnly) {
  EXPECT_TRUE(SameSecret("Bearer abc", "Bearer abc"));
  EXPECT_FALSE(SameSecret("Bearer abd", "Bearer abc"));
  EXPECT_FALSE(SameSecret("Bearer ab", "Bearer abc"));
  EXPECT_FALSE(SameSecret("Bearer abcd", "Bearer abc"));
  EXPECT_FALSE(SameSecret("", "Bearer abc"));
  EXPECT_TRUE(SameSecret("", ""));
}

}  // namespace
}  // namespace trailmark::server
