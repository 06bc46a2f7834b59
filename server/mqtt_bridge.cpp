// SPDX-License-Identifier: MIT
#include "server/mqtt_bridge.h"

#include <mqtt/async_client.h>

#include <chrono>
#include <stdexcept>
#include <thread>

namespace trailmark::server {

struct MqttBridge::Impl {
  std::unique_ptr<mqtt::async_client> client;
};

MqttBridge::MqttBridge(MqttOptions options, IngestFn ingest, StatusFn status, RejectFn reject)
    : impl_(new Impl),
      options_(std::move(options)),
      ingest_(std::move(ingest)),
      status_(std::move(status)),
      reject_(std::move(reject)) {}

MqttBridge::~MqttBridge() { Stop(); }

void MqttBridge::Start() {
  try {
    impl_->client = options_.persist_dir.empty()
                        ? std::make_unique<mqtt::async_client>(options_.uri, options_.client_id)
                        : std::make_unique<mqtt::async_client>(options_.uri, options_.client_id,
                                                               options_.persist_dir);
    const std::string prefix = "trailmark/" + options_.incident + "/";
    impl_->client->set_message_callback([this, prefix](mqtt::const_message_ptr msg) {
      ++stats_.received;
      const std::string topic = msg->get_topic();
      // trailmark/<incident>/<node>/<leaf>
      const std::string rest = topic.rfind(prefix, 0) == 0 ? topic.substr(prefix.size()) : "";
      const auto slash = rest.find('/');
      if (slash == std::string::npos) {
        ++stats_.rejected;
        reject_(topic + ": not trailmark/<incident>/<node>/<stream>");
        return;
      }
      const std::string node = rest.substr(0, slash), leaf = rest.substr(slash + 1);
      if (leaf == "estimate") return;  // our own publications
      if (leaf == "status") {
        status_(node, msg->to_string());
        return;
      }
      // The PUBACK leaves when this callback returns: only after the journal commit. A journal
      // that cannot commit (disk full) holds the callback, retrying every second, so nothing
      // is acknowledged that is not on disk; the broker keeps what follows.
      for (int attempt = 0;; ++attempt) {
        try {
          ingest_(leaf, msg->to_string());
          ++stats_.ingested;
        } catch (const std::invalid_argument&) {
          ++stats_.rejected;  // malformed: counted (the server logged why), never crashes it
        } catch (const std::exception& e) {
          if (attempt == 0) reject_(topic + ": " + e.what() + " (retrying)");
          if (!stopping_) {
            std::this_thread::sleep_for(std::chrono::seconds(1));
            continue;
          }
          ++stats_.rejected;
        }
        break;
      }
    });
    auto opts =
        mqtt::connect_options_builder().clean_session(false).automatic_reconnect(true).finalize();
    if (!options_.username.empty()) {
      opts.set_user_name(options_.username);
      opts.set_password(options_.password);
    }
    if (options_.uri.rfind("ssl://", 0) == 0 || options_.uri.rfind("mqtts://", 0) == 0) {
      auto ssl = mqtt::ssl_options_builder().enable_server_cert_auth(true).verify(true);
      if (!options_.ca_file.empty()) ssl.trust_store(options_.ca_file);
      opts.set_ssl(ssl.finalize());
    }
    impl_->client->connect(opts)->wait();
    impl_->client->subscribe(prefix + "+/+", 1)->wait();
  } catch (const mqtt::exception& e) {
    throw std::runtime_error("serve: MQTT broker " + options_.uri + ": " + e.what());
  }
}

void MqttBridge::Stop() {
  stopping_ = true;
  if (!impl_ || !impl_->client) return;
  try {
    if (impl_->client->is_connected()) impl_->client->disconnect()->wait();
  } catch (const mqtt::exception&) {
  }
  impl_->client.reset();
}

void MqttBridge::PublishEstimate(const std::string& node, const std::string& json) {
  if (!impl_->client || !impl_->client->is_connected()) return;
  try {
    impl_->client->publish(mqtt::make_message(
        "trailmark/" + options_.incident + "/" + node + "/estimate", json, 1, true));
    ++stats_.published;
  } catch (const mqtt::exception&) {
  }
}

}  // namespace trailmark::server
