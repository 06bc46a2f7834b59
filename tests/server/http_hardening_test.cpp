// SPDX-License-Identifier: MIT
// Strangers cannot stall or bloat the live server (issue 30, item 2): the token is checked on
// the headers before any body is read, the size limit holds for chunked bodies, the token
// comparison does not depend on where the first wrong byte is, a request's headers have a
// deadline, the whole request another, one client address a cap on its connections and the
// connections waiting for a worker a cap in total. Raw sockets on loopback, so the
// test sends exactly what a hostile client would (headers alone, endless chunks).
#include <arpa/inet.h>
#include <netinet/in.h>
#include <poll.h>
#include <sys/socket.h>
#include <unistd.h>

#include <gtest/gtest.h>

#include <chrono>
#include <memory>
#include <optional>
#include <string>
#include <thread>
#include <vector>

#include "server/connection_limits.h"
#include "server/incident_server.h"
#include "server/live_server_fixture.h"
#include "test_util.h"

namespace trailmark::server {
namespace {


std::string ChunkedHeaders(const std::string& token) {
  return "POST /api/ingest/steps.csv HTTP/1.1\r\nHost: 127.0.0.1\r\n" +
         (token.empty() ? std::string() : "Authorization: Bearer " + token + "\r\n") +
         "Content-Type: text/csv\r\nTransfer-Encoding: chunked\r\n\r\n";
}

TEST_F(LiveServerFixture, JsonRepliesAreSentAsTheyAreEvenToABrowserThatAcceptsBrotli) {
  // A browser accepts brotli; Debian's cpp-httplib compressed "application/json" replies with it
  // at quality 11 (15 s of CPU for a 4-hour incident's history). Replies carry their charset and
  // no content encoding, refusals included.
  for (const std::string& token : {std::string("s3cret-token"), std::string("wrong")}) {
    for (const char* path : {"/api/state", "/api/history", "/api/floorplan", "/api/health"}) {
      Connection c(server_->port());
      ASSERT_TRUE(c.connected());
      ASSERT_TRUE(c.Send(std::string("GET ") + path + " HTTP/1.1\r\nHost: 127.0.0.1\r\n" +
                         "Authorization: Bearer " + token + "\r\n" +
                         "Accept-Encoding: gzip, deflate, br\r\nConnection: close\r\n\r\n"));
      const std::string reply = c.Receive(std::chrono::milliseconds(5000));
      ASSERT_NE(reply.find("\r\n\r\n"), std::string::npos) << path << ": " << reply;
      const std::string headers = reply.substr(0, reply.find("\r\n\r\n"));
      EXPECT_EQ(headers.find("Content-Encoding"), std::string::npos) << path << ": " << headers;
      EXPECT_NE(headers.find("Content-Type: application/json; charset=utf-8"), std::string::npos)
          << path << ": " << headers;
    }
  }
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

bool Answered(Connection& c, const char* status) {
  return c.Receive(std::chrono::milliseconds(3000)).find(status) != std::string::npos;
}

const std::string kHealth = "GET /api/health HTTP/1.1\r\nHost: x\r\n\r\n";

/// Sends `bytes` one every 0.3 s until the server cuts the connection; how long that took
/// (nullopt: never cut).
std::optional<std::chrono::steady_clock::duration> TrickleUntilCut(Connection& c,
                                                                 const std::string& bytes) {
  const auto t0 = std::chrono::steady_clock::now();
  for (std::size_t i = 0; i < bytes.size(); ++i) {
    bool cut = !c.Send(bytes.substr(i, 1));
    std::this_thread::sleep_for(std::chrono::milliseconds(300));
    cut = cut || !c.Open();
    if (cut) return std::chrono::steady_clock::now() - t0;
  }
  return std::nullopt;
}

/// Whether a health request from `from` is answered within 3 s of retries (a closed
/// connection's place is freed as soon as the server sees it close).
bool ServedSoon(int port, const char* from = nullptr) {
  for (int i = 0; i < 30; ++i) {
    Connection c(port, from);
    if (c.Send(kHealth) && Answered(c, " 200 ")) return true;
    std::this_thread::sleep_for(std::chrono::milliseconds(100));
  }
  return false;
}

TEST_F(LiveServerFixture, HeadersThatComeTooSlowlyAreCutOff) {
  // A byte every 0.3 s keeps within the 5 s per-read timeout for ever; the 1 s deadline of the
  // whole head closes the connection.
  Restart(1.0, 32, 64);
  Connection slow(server_->port());
  ASSERT_TRUE(slow.connected());
  const auto took = TrickleUntilCut(
      slow, "GET /api/health HTTP/1.1\r\nHost: x\r\nX-Slow: aaaaaaaaaaaaaaaa\r\n");
  ASSERT_TRUE(took.has_value()) << "the slow head was never cut off";
  EXPECT_LT(*took, std::chrono::milliseconds(4000));
  EXPECT_GE(*took, std::chrono::milliseconds(900));
  // A client that sends its head at once is served on the same server.
  Connection quick(server_->port());
  ASSERT_TRUE(quick.Send(kHealth));
  EXPECT_TRUE(Answered(quick, " 200 "));
}

TEST_F(LiveServerFixture, OneAddressCannotTakeEveryWorker) {
  // 8 workers, 3 connections per address. A stranger (127.0.0.2) opens 12 connections that
  // send half a head and stall: 3 hold workers, the others are answered 503 at once. A device
  // from 127.0.0.1 is served meanwhile.
  Restart(30.0, 3, 8);
  std::vector<std::unique_ptr<Connection>> stranger;
  for (int i = 0; i < 12; ++i) {
    stranger.push_back(std::make_unique<Connection>(server_->port(), "127.0.0.2"));
    ASSERT_TRUE(stranger.back()->connected());
    ASSERT_TRUE(stranger.back()->Send("GET /api/health HTTP/1.1\r\nHost: x\r\n"));
  }
  std::size_t busy = 0;
  for (auto& c : stranger) busy += c->Receive(std::chrono::milliseconds(1500)).find(" 503 ") != std::string::npos;
  EXPECT_EQ(busy, 9u);
  const std::string stats = server_->StatsJson().dump();
  EXPECT_NE(stats.find("\"connections_refused_per_address\":9"), std::string::npos) << stats;
  const auto t0 = std::chrono::steady_clock::now();
  Connection device(server_->port(), "127.0.0.1");
  ASSERT_TRUE(device.Send(kHealth));
  EXPECT_TRUE(Answered(device, " 200 "));
  EXPECT_LT(std::chrono::steady_clock::now() - t0, std::chrono::milliseconds(2000));
  // Closing the stranger's connections frees its places (as soon as the server sees them close).
  stranger.clear();
  EXPECT_TRUE(ServedSoon(server_->port(), "127.0.0.2"));
}

TEST_F(LiveServerFixture, ABodyThatComesTooSlowlyIsCutOff) {
  // A device's headers at once, then its body a byte every 0.3 s: the 2 s deadline of the whole
  // request closes it; nothing is ingested.
  Restart(1.0, 32, 64, 2.0);
  Connection slow(server_->port());
  ASSERT_TRUE(slow.Send("POST /api/ingest/steps.csv HTTP/1.1\r\nHost: x\r\nAuthorization: Bearer "
                        "s3cret-token\r\nContent-Type: text/csv\r\nContent-Length: 200\r\n\r\n"));
  const auto took = TrickleUntilCut(slow, "t0,t1,agent,dx,dy\n0,1,ff1,0.7,0\n1,2,ff1,0.7,0\n");
  ASSERT_TRUE(took.has_value()) << "the slow body was never cut off";
  EXPECT_LT(*took, std::chrono::milliseconds(5000));
  EXPECT_GE(*took, std::chrono::milliseconds(1800));
  EXPECT_EQ(server_->stats().ingested_rows.load(), 0u);
  const std::string stats = server_->StatsJson().dump();
  EXPECT_NE(stats.find("\"request_deadlines_missed\":1"), std::string::npos) << stats;
  // Its refusal closes the connection: the rest of its body is not read as a next request.
  EXPECT_NE(stats.find("\"header_deadlines_missed\":0"), std::string::npos) << stats;
}

TEST_F(LiveServerFixture, ConnectionsBeyondTheWaitingCapAreRefusedAtOnce) {
  // 4 workers, 2 connections may wait, no cap per address: 4 stalled heads hold the workers,
  // 2 more wait, and the 7th is answered 503 at once by the accepting thread.
  Restart(30.0, 0, 4, 60.0, 2);
  std::vector<std::unique_ptr<Connection>> held;
  for (int i = 0; i < 6; ++i) {
    held.push_back(std::make_unique<Connection>(server_->port()));
    ASSERT_TRUE(held.back()->Send("GET /api/health HTTP/1.1\r\nHost: x\r\n"));
    std::this_thread::sleep_for(std::chrono::milliseconds(50));
  }
  Connection seventh(server_->port());
  const auto t0 = std::chrono::steady_clock::now();
  EXPECT_TRUE(Answered(seventh, " 503 "));
  EXPECT_LT(std::chrono::steady_clock::now() - t0, std::chrono::milliseconds(1000));
  const std::string stats = server_->StatsJson().dump();
  EXPECT_NE(stats.find("\"connections_refused_waiting\":1"), std::string::npos) << stats;
  held.clear();  // the workers are free again: a request is served
  EXPECT_TRUE(ServedSoon(server_->port()));
}

TEST(AddressCounter, CountsPlacesPerAddress) {
  AddressCounter c(2);
  EXPECT_TRUE(c.Admit("a"));
  EXPECT_TRUE(c.Admit("a"));
  EXPECT_FALSE(c.Admit("a"));
  EXPECT_TRUE(c.Admit("b"));
  EXPECT_EQ(c.Open("a"), 2u);
  c.Release("a");
  EXPECT_TRUE(c.Admit("a"));
  c.Release("x");  // unknown: nothing happens
  EXPECT_EQ(c.Open("x"), 0u);
  AddressCounter unlimited(0);
  for (int i = 0; i < 1000; ++i) EXPECT_TRUE(unlimited.Admit("a"));
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
