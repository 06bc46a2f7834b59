// SPDX-License-Identifier: MIT
#pragma once
/// Field devices over MQTT (issue 7): the server subscribes, with a persistent session and
/// QoS 1, to the incident's topic tree
///   trailmark/<incident>/<node>/<stream>   payload: a CSV document of the mission format
///                                          (steps.csv, rssi.csv, ...) -> journaled, then acked
///   trailmark/<incident>/<node>/status     payload: "online" / "lost" (devices set "lost" as
///                                          their retained last will) -> a device-lost alert
/// and publishes every agent's latest estimate, retained, QoS 1, to
///   trailmark/<incident>/<node>/estimate   payload: the node's JSON of GET /api/state.
/// The PUBACK of an ingested message leaves only after the journal commit (the message
/// callback returns after Journal::Append). Eclipse Paho C++ (Debian libpaho-mqttpp-dev).

#include <atomic>
#include <functional>
#include <memory>
#include <nlohmann/json.hpp>
#include <string>

namespace trailmark::server {

struct MqttOptions {
  std::string uri;  ///< e.g. tcp://127.0.0.1:1883 (ssl://... for TLS)
  std::string incident = "incident";
  std::string client_id = "trailmark-server";
  std::string username, password;
  std::string persist_dir;  ///< client-side persistence of outgoing QoS 1 messages
  std::string ca_file;      ///< ssl:// URIs: the CA certificate (PEM) that signed the broker's
};

struct MqttStats {
  std::atomic<std::size_t> received{0}, ingested{0}, rejected{0}, published{0};
};

class MqttBridge {
 public:
  using IngestFn =
      std::function<nlohmann::json(const std::string& stream, const std::string& body)>;
  using StatusFn = std::function<void(const std::string& node, const std::string& status)>;
  using RejectFn = std::function<void(const std::string& reason)>;
  /// `reject` receives the reason of every message dropped as malformed (also counted).
  MqttBridge(MqttOptions options, IngestFn ingest, StatusFn status, RejectFn reject);
  ~MqttBridge();
  /// Connects (persistent session) and subscribes; throws std::runtime_error when it cannot.
  void Start();
  void Stop();
  /// Retained QoS 1 estimate of a node.
  void PublishEstimate(const std::string& node, const std::string& json);
  const MqttStats& stats() const { return stats_; }

 private:
  struct Impl;
  std::unique_ptr<Impl> impl_;
  MqttOptions options_;
  IngestFn ingest_;
  StatusFn status_;
  RejectFn reject_;
  MqttStats stats_;
  std::atomic<bool> stopping_{false};
};

}  // namespace trailmark::server
