// SPDX-License-Identifier: MIT
#pragma once
/// The live server under load (issue 7, item 7), on loopback in one process: N simulated
/// firefighters (or the agents of a given mission: LoadTestOptions::mission), each a client
/// thread that POSTs its foot IMU (100 Hz; else its steps) in batches and its other rows as
/// fast as the server acknowledges them, and one dashboard client on the event
/// stream (server-sent events). Reports sustained rows/s, end-to-end latency (the POST of a
/// batch -> the first event whose state has that firefighter's estimate at or past the batch's
/// last sample), journal commits, CPU and peak memory. Not a unit test: `trailmark bench load`.

#include <cstdint>
#include <filesystem>
#include <map>
#include <nlohmann/json.hpp>
#include <string>

namespace trailmark::server {

struct LoadTestOptions {
  int firefighters = 20;
  double minutes = 10.0;    ///< incident time each firefighter sends
  double batch_s = 0.1;     ///< IMU per request (10 samples at 100 Hz)
  double imu_hz = 100.0;
  /// Devices keep within this much mission time of each other (s), as they do in real time;
  /// 0: each sends as fast as it can.
  double max_skew_s = 0.5;
  /// > 0: devices send at this multiple of real time (a window is sent no earlier than its
  /// mission time since the first row, divided by speed, after the start), as a live incident
  /// sends (1) or a replay faster than life; 0: as fast as the server acknowledges.
  double speed = 0.0;
  /// Firefighter k (1-based) starts its walk (k - 1) x this later (s): teams enter one after
  /// another; 0: all at once and in step (every drop, turn and stop at the same instants).
  double stagger_s = 0.0;
  /// Each device's streams of a batch window in one request (POST /api/ingest, as a device
  /// should send them); false: one request per stream (POST /api/ingest/<stream>). MQTT: per
  /// stream always (a topic per stream).
  bool bundle = true;
  std::string pipeline = "ins";  ///< a name of the registry
  std::map<std::string, std::string> pipeline_options;
  /// Where the journal goes (a real disk: each group commit is an fsync).
  std::filesystem::path work_dir;
  /// Empty: devices POST over HTTP. Else the broker (e.g. tcp://127.0.0.1:1883) that devices
  /// publish to with QoS 1 and the server subscribes to.
  std::string mqtt_uri;
  std::uint64_t seed = 1;
  /// Not empty: this mission directory is replayed as it is, instead of a simulation
  /// (firefighters, minutes, imu_hz, stagger_s and seed then do not apply): each agent with
  /// an imu.csv or steps.csv stream is a device that sends the rows it is the device of, in
  /// batches of batch_s of its IMU (else of its steps); the other nodes' rows go with the
  /// first device's; the pipeline gets the mission's floor plan.
  std::filesystem::path mission;
};

/// Runs the load test; throws std::runtime_error when the server refuses rows or loses any
/// (the journal must end with exactly the rows sent).
nlohmann::json RunLoadTest(const LoadTestOptions& options);

}  // namespace trailmark::server
