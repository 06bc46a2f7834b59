// SPDX-License-Identifier: MIT
#include "server/gated_http_server.h"

#include <arpa/inet.h>
#include <netinet/in.h>
#include <poll.h>
#include <sys/socket.h>
#include <fcntl.h>
#include <fmt/format.h>
#include <openssl/err.h>
#include <openssl/ssl.h>
#include <unistd.h>

#include <algorithm>
#include <cerrno>
#include <chrono>
#include <cmath>
#include <cstring>
#include <string_view>
#include <type_traits>

namespace trailmark::server {

namespace {

using Clock = std::chrono::steady_clock;

/// The address and port of a socket's peer (`peer`) or its own end.
bool Endpoint(socket_t sock, bool peer, std::string& ip, int& port) {
  sockaddr_storage a{};
  socklen_t len = sizeof a;
  const int rc = peer ? getpeername(sock, reinterpret_cast<sockaddr*>(&a), &len)
                      : getsockname(sock, reinterpret_cast<sockaddr*>(&a), &len);
  if (rc != 0) return false;
  char text[INET6_ADDRSTRLEN] = {};
  if (a.ss_family == AF_INET) {
    const auto* v4 = reinterpret_cast<const sockaddr_in*>(&a);
    inet_ntop(AF_INET, &v4->sin_addr, text, sizeof text);
    port = ntohs(v4->sin_port);
  } else if (a.ss_family == AF_INET6) {
    const auto* v6 = reinterpret_cast<const sockaddr_in6*>(&a);
    inet_ntop(AF_INET6, &v6->sin6_addr, text, sizeof text);
    port = ntohs(v6->sin6_port);
  } else {
    return false;
  }
  ip = text;
  return true;
}

/// poll() for `events` up to `timeout`; > 0 when ready.
int Wait(socket_t sock, short events, std::chrono::milliseconds timeout) {
  pollfd p{sock, events, 0};
  const auto ms = std::max<long long>(0, timeout.count());
  int rc;
  do {
    rc = poll(&p, 1, static_cast<int>(std::min<long long>(ms, 1 << 30)));
  } while (rc < 0 && errno == EINTR);
  return rc;
}

std::chrono::milliseconds Ms(time_t sec, time_t usec) {
  return std::chrono::milliseconds(sec * 1000 + usec / 1000);
}

/// The library's socket stream, with a deadline for each request's line and headers: reads
/// before the blank line that ends them wait at most until the deadline; after it, the
/// library's per-read timeout as before. One per connection: bytes read ahead (a pipelined
/// request) stay for the next request. Reads are buffered as the library's own stream's are
/// (its header parser asks for one byte at a time).
class DeadlineStream final : public httplib::Stream {
 public:
  /// `ssl`: the connection's TLS session (its socket non-blocking), null for plain HTTP.
  DeadlineStream(socket_t sock, SSL* ssl, std::chrono::milliseconds read_timeout,
                 std::chrono::milliseconds write_timeout)
      : sock_(sock), ssl_(ssl), read_timeout_(read_timeout), write_timeout_(write_timeout) {}

  /// A new request starts (its first byte is here or buffered): its head is due by
  /// `head_deadline`, the whole of it by `request_deadline` (until its response starts).
  void BeginRequest(Clock::time_point head_deadline, Clock::time_point request_deadline) {
    deadline_ = head_deadline;
    request_deadline_ = request_deadline;
    matched_ = 0;
    head_done_ = false;
    responding_ = false;
    close_after_ = false;
    deadline_missed_ = false;
    request_deadline_missed_ = false;
  }
  bool deadline_missed() const { return deadline_missed_; }
  bool request_deadline_missed() const { return request_deadline_missed_; }
  bool close_after() const { return close_after_; }
  bool buffered() const { return begin_ < end_ || (ssl_ != nullptr && SSL_pending(ssl_) > 0); }

  bool is_readable() const override {
    if (buffered()) return true;
    if (Wait(sock_, POLLIN, ReadWait()) > 0) return !DeadlinePassed();
    DeadlinePassed();
    return false;
  }
  bool is_writable() const override { return Wait(sock_, POLLOUT, write_timeout_) > 0; }

  ssize_t read(char* ptr, size_t size) override {
    if (size == 0) return 0;
    if (begin_ == end_) {
      const ssize_t n = Fill();
      if (n <= 0) return n;
    }
    const std::size_t n = std::min(size, end_ - begin_);
    std::memcpy(ptr, buffer_ + begin_, n);
    begin_ += n;
    if (!head_done_) Scan(std::string_view(ptr, n));
    return static_cast<ssize_t>(n);
  }

  ssize_t write(const char* ptr, size_t size) override {
    // The response starts (an interim "100 Continue" is not it): the request has been read.
    const std::string_view bytes(ptr, size);
    if (!responding_ && !bytes.starts_with("HTTP/1.1 100")) {
      responding_ = true;
      // A response that closes the connection (a refused request whose body was not read):
      // what follows on it is not a next request.
      const auto head_end = bytes.find("\r\n\r\n");
      close_after_ = bytes.substr(0, head_end).find("\r\nConnection: close\r\n") !=
                     std::string_view::npos;
    }
    if (ssl_ != nullptr) {
      // Non-blocking: a retry passes the same bytes, as OpenSSL requires.
      for (;;) {
        const int r = SSL_write(ssl_, ptr, static_cast<int>(std::min<size_t>(size, 1 << 30)));
        if (r > 0) return r;
        const short ev = Want(r);
        if (ev == 0 || Wait(sock_, ev, write_timeout_) <= 0) return -1;
      }
    }
    if (!is_writable()) return -1;
    ssize_t n;
    do {
      n = send(sock_, ptr, size, MSG_NOSIGNAL);
    } while (n < 0 && errno == EINTR);
    return n;
  }

  void get_remote_ip_and_port(std::string& ip, int& port) const override {
    if (!Endpoint(sock_, true, ip, port)) ip.clear(), port = 0;
  }
  void get_local_ip_and_port(std::string& ip, int& port) const override {
    if (!Endpoint(sock_, false, ip, port)) ip.clear(), port = 0;
  }
  socket_t socket() const override { return sock_; }

 private:
  // What a failed TLS call waits for: POLLIN, POLLOUT, or 0 (an error, or the peer closed).
  short Want(int r) const {
    const int e = SSL_get_error(ssl_, r);
    return e == SSL_ERROR_WANT_READ ? POLLIN : e == SSL_ERROR_WANT_WRITE ? POLLOUT : 0;
  }
  // Reads what has come into the buffer: > 0 bytes, 0 when the peer closed, -1 on a timeout,
  // a missed deadline or an error.
  ssize_t Fill() {
    // A deadline holds however steadily bytes trickle in (what is buffered has come already).
    if (DeadlinePassed()) return -1;
    for (;;) {
      if (ssl_ != nullptr) {
        const int r = SSL_read(ssl_, buffer_, sizeof buffer_);
        if (r > 0) {
          begin_ = 0;
          end_ = static_cast<std::size_t>(r);
          return r;
        }
        if (SSL_get_error(ssl_, r) == SSL_ERROR_ZERO_RETURN) return 0;
        const short ev = Want(r);
        if (ev == 0) return -1;
        if (Wait(sock_, ev, ReadWait()) <= 0 || DeadlinePassed()) {
          DeadlinePassed();
          return -1;
        }
        continue;
      }
      if (Wait(sock_, POLLIN, ReadWait()) <= 0) {
        DeadlinePassed();
        return -1;
      }
      ssize_t n;
      do {
        n = recv(sock_, buffer_, sizeof buffer_, 0);
      } while (n < 0 && errno == EINTR);
      if (n <= 0) return n;
      begin_ = 0;
      end_ = static_cast<std::size_t>(n);
      return n;
    }
  }
  // Whether the request's head or the request is overdue (noted for the log).
  bool DeadlinePassed() const {
    const auto now = Clock::now();
    if (!head_done_ && now >= deadline_) deadline_missed_ = true;
    if (!responding_ && now >= request_deadline_) request_deadline_missed_ = true;
    return deadline_missed_ || request_deadline_missed_;
  }
  std::chrono::milliseconds ReadWait() const {
    if (responding_) return read_timeout_;
    const auto due = head_done_ ? request_deadline_ : std::min(deadline_, request_deadline_);
    // Rounded up: a wait that ends before the deadline would fail a read that is not overdue.
    const auto left = std::chrono::ceil<std::chrono::milliseconds>(due - Clock::now());
    return std::clamp(left, std::chrono::milliseconds(0), read_timeout_);
  }
  // The head ends at the first CRLF CRLF of the bytes handed to the library (a small matcher
  // across reads).
  void Scan(std::string_view bytes) {
    static constexpr std::string_view kEnd = "\r\n\r\n";
    for (const char c : bytes) {
      matched_ = c == kEnd[matched_] ? matched_ + 1 : (c == '\r' ? 1 : 0);
      if (matched_ == kEnd.size()) {
        head_done_ = true;
        return;
      }
    }
  }
  socket_t sock_;
  SSL* ssl_;
  std::chrono::milliseconds read_timeout_, write_timeout_;
  Clock::time_point deadline_{}, request_deadline_{};
  std::size_t matched_ = 0;
  bool head_done_ = false;
  bool responding_ = false;
  bool close_after_ = false;
  mutable bool deadline_missed_ = false;
  mutable bool request_deadline_missed_ = false;
  char buffer_[4096];
  std::size_t begin_ = 0, end_ = 0;
};

/// Set while the accepting thread runs a connection it cannot queue: refuse it.
thread_local bool t_refuse = false;

void Refuse(socket_t sock) {
  static constexpr std::string_view kBusy =
      "HTTP/1.1 503 Service Unavailable\r\nContent-Length: 0\r\nRetry-After: 1\r\n"
      "Connection: close\r\n\r\n";
  (void)send(sock, kBusy.data(), kBusy.size(), MSG_NOSIGNAL | MSG_DONTWAIT);
}

void CloseSocket(socket_t sock) {
  shutdown(sock, SHUT_RDWR);
  close(sock);
}

/// The TLS handshake of an accepted connection, by `deadline`: its session (the socket made
/// non-blocking), or null.
SSL* Handshake(socket_t sock, SSL_CTX* ctx, Clock::time_point deadline) {
  const int flags = fcntl(sock, F_GETFL, 0);
  if (flags < 0 || fcntl(sock, F_SETFL, flags | O_NONBLOCK) != 0) return nullptr;
  SSL* ssl = SSL_new(ctx);
  if (ssl == nullptr) return nullptr;
  if (SSL_set_fd(ssl, sock) != 1) {
    SSL_free(ssl);
    return nullptr;
  }
  for (;;) {
    const int r = SSL_accept(ssl);
    if (r == 1) return ssl;
    const int e = SSL_get_error(ssl, r);
    const short ev = e == SSL_ERROR_WANT_READ ? POLLIN : e == SSL_ERROR_WANT_WRITE ? POLLOUT : 0;
    const auto left = std::chrono::ceil<std::chrono::milliseconds>(deadline - Clock::now());
    if (ev == 0 || left.count() <= 0 || Wait(sock, ev, left) <= 0) {
      SSL_free(ssl);
      return nullptr;
    }
  }
}

}  // namespace

bool ConnectionLimits::IsValid(std::string* why) const {
  if (!(header_deadline_s > 0) || !std::isfinite(header_deadline_s) ||
      !(request_deadline_s >= header_deadline_s) || !std::isfinite(request_deadline_s)) {
    if (why) *why = "the header deadline must be positive and the request deadline at least it";
    return false;
  }
  return true;
}

BoundedThreadPool::BoundedThreadPool(std::size_t threads, std::size_t max_waiting)
    : max_waiting_(max_waiting) {
  for (std::size_t i = 0; i < threads; ++i) threads_.emplace_back([this] { Work(); });
}

BoundedThreadPool::~BoundedThreadPool() {
  if (!threads_.empty()) shutdown();
}

void BoundedThreadPool::enqueue(std::function<void()> fn) {
  {
    std::unique_lock lock(mutex_);
    if (jobs_.size() < max_waiting_) {
      jobs_.push_back(std::move(fn));
      lock.unlock();
      cond_.notify_one();
      return;
    }
  }
  // Too many waiting: the connection is refused here, at once (the job sees t_refuse).
  t_refuse = true;
  fn();
  t_refuse = false;
}

void BoundedThreadPool::shutdown() {
  {
    std::lock_guard lock(mutex_);
    shutdown_ = true;
  }
  cond_.notify_all();
  for (auto& t : threads_) t.join();
  threads_.clear();
}

void BoundedThreadPool::Work() {
  for (;;) {
    std::function<void()> fn;
    {
      std::unique_lock lock(mutex_);
      cond_.wait(lock, [&] { return !jobs_.empty() || shutdown_; });
      if (shutdown_ && jobs_.empty()) return;
      fn = std::move(jobs_.front());
      jobs_.pop_front();
    }
    fn();
  }
}

bool AddressCounter::Admit(const std::string& address) {
  std::lock_guard lock(mutex_);
  std::size_t& n = open_[address];
  if (cap_ > 0 && n >= cap_) {
    if (n == 0) open_.erase(address);
    return false;
  }
  ++n;
  return true;
}

void AddressCounter::Release(const std::string& address) {
  std::lock_guard lock(mutex_);
  const auto it = open_.find(address);
  if (it == open_.end()) return;
  if (--it->second == 0) open_.erase(it);
}

std::size_t AddressCounter::Open(const std::string& address) const {
  std::lock_guard lock(mutex_);
  const auto it = open_.find(address);
  return it == open_.end() ? 0 : it->second;
}

httplib::TaskQueue* GateCore::NewTaskQueue(std::size_t threads) const {
  return new BoundedThreadPool(threads, limits_.max_waiting);
}

GateCore::GateCore(ConnectionLimits limits, std::function<void(const std::string&)> log)
    : limits_(limits), log_(std::move(log)), addresses_(limits.max_per_address) {}

void GateCore::Note(std::atomic<std::size_t>& counter, const std::string& what) {
  const std::size_t n = ++counter;
  // 1, 10, 100, ...: the first of each kind and then every power of ten.
  std::size_t p = 1;
  while (p < n) p *= 10;
  if (p == n && log_) log_(what + " (" + std::to_string(n) + " so far)");
}

template <class Base>
bool Gated<Base>::process_and_close_socket(socket_t sock) {
  constexpr bool kTls = std::is_same_v<Base, httplib::SSLServer>;
  std::string address;
  int port = 0;
  if (!Endpoint(sock, true, address, port)) address.assign(1, '?');
  // Counted before the answer: whoever reads the 503 finds it in /api/stats. (Over TLS the
  // connection is closed without one: a plain answer means nothing to a TLS client.)
  auto refuse = [&](std::atomic<std::size_t>& counter, const std::string& why) {
    Note(counter, fmt::format("connection from {} refused: {} (503)", address, why));
    if (!kTls) Refuse(sock);
    CloseSocket(sock);
    return false;
  };
  if (t_refuse) {
    return refuse(stats_.refused_waiting,
                  fmt::format("{} connections wait for a worker already", limits_.max_waiting));
  }
  if (!addresses_.Admit(address)) {
    return refuse(stats_.refused_per_address,
                  fmt::format("it holds {} connections already", limits_.max_per_address));
  }
  const auto deadline = std::chrono::duration_cast<Clock::duration>(
      std::chrono::duration<double>(limits_.header_deadline_s));
  const auto request_deadline = std::chrono::duration_cast<Clock::duration>(
      std::chrono::duration<double>(limits_.request_deadline_s));
  SSL* ssl = nullptr;
  if constexpr (kTls) {
    // The handshake within the header deadline too (a stranger's half handshake holds a
    // worker no longer than a half request).
    ssl = Handshake(sock, this->ssl_context(), Clock::now() + deadline);
    if (ssl == nullptr) {
      Note(stats_.handshakes_failed,
           fmt::format("connection from {} closed: no TLS handshake within {:g} s", address,
                       limits_.header_deadline_s));
      ERR_clear_error();
      addresses_.Release(address);
      CloseSocket(sock);
      return false;
    }
  }
  // The library's keep-alive loop (process_server_socket_core in cpp-httplib 0.11): up to
  // keep_alive_max_count_ requests, each awaited for keep_alive_timeout_sec_ — here in slices,
  // so that a stopped server does not wait for its idle connections.
  bool ret = false;
  DeadlineStream strm(sock, ssl, Ms(this->read_timeout_sec_, this->read_timeout_usec_),
                      Ms(this->write_timeout_sec_, this->write_timeout_usec_));
  for (std::size_t count = this->keep_alive_max_count_; count > 0; --count) {
    bool readable = strm.buffered();
    const auto idle_until = Clock::now() + std::chrono::seconds(this->keep_alive_timeout_sec_);
    while (!readable && this->svr_sock_ != INVALID_SOCKET && Clock::now() < idle_until) {
      const int rc = Wait(sock, POLLIN, std::chrono::milliseconds(100));
      if (rc < 0) break;
      if (rc > 0) {
        readable = true;
        break;
      }
    }
    if (!readable || this->svr_sock_ == INVALID_SOCKET) break;
    const auto now = Clock::now();
    strm.BeginRequest(now + deadline, now + request_deadline);
    bool connection_closed = false;
    ret = this->process_request(strm, count == 1, connection_closed, nullptr);
    if (strm.deadline_missed()) {
      Note(stats_.header_deadlines,
           fmt::format("connection from {} closed: its request's headers took longer than {:g} s",
                       address, limits_.header_deadline_s));
    }
    if (strm.request_deadline_missed() && !strm.deadline_missed()) {
      Note(stats_.request_deadlines,
           fmt::format("connection from {} closed: its request took longer than {:g} s",
                       address, limits_.request_deadline_s));
    }
    if (!ret || connection_closed || strm.close_after()) break;
  }
  if (ssl != nullptr) {
    SSL_shutdown(ssl);  // non-blocking: the close_notify is sent if it can be, not awaited
    SSL_free(ssl);
    ERR_clear_error();
  }
  addresses_.Release(address);
  CloseSocket(sock);
  return ret;
}

template class Gated<httplib::Server>;
template class Gated<httplib::SSLServer>;

}  // namespace trailmark::server
