#include "services/mqtt/mqtt_client.h"

#include <mosquitto.h>
#include <spdlog/spdlog.h>

#include <chrono>
#include <stdexcept>

#include "common/util/clock.h"

namespace cnc::mqtt {
namespace {

void check(int rc, const std::string& what) {
  if (rc != MOSQ_ERR_SUCCESS) throw std::runtime_error(what + ": " + mosquitto_strerror(rc));
}

// libmosquitto's global set-up, once per process.
struct Library {
  Library() { mosquitto_lib_init(); }
  ~Library() { mosquitto_lib_cleanup(); }
};

}  // namespace

MqttClient::MqttClient(const ClientOptions& o) : o_(o) {
  static Library library;
  m_ = mosquitto_new(o_.client_id.c_str(), o_.clean_session, this);
  if (m_ == nullptr) throw std::runtime_error("mqtt: cannot make a client with id '" + o_.client_id + "'");
  check(mosquitto_int_option(m_, MOSQ_OPT_PROTOCOL_VERSION, MQTT_PROTOCOL_V311), "mqtt: protocol 3.1.1");
  check(mosquitto_threaded_set(m_, true), "mqtt: threads");
  if (!o_.will.topic.empty())
    check(mosquitto_will_set(m_, o_.will.topic.c_str(), static_cast<int>(o_.will.payload.size()), o_.will.payload.data(),
                             1, o_.will.retained),
          "mqtt: the last will on " + o_.will.topic);
  if (!o_.username.empty())
    check(mosquitto_username_pw_set(m_, o_.username.c_str(), o_.password.empty() ? nullptr : o_.password.c_str()),
          "mqtt.username");
  if (!o_.ca_file.empty()) {
    check(mosquitto_tls_set(m_, o_.ca_file.c_str(), nullptr, o_.cert_file.empty() ? nullptr : o_.cert_file.c_str(),
                            o_.key_file.empty() ? nullptr : o_.key_file.c_str(), nullptr),
          "mqtt.ca_file " + o_.ca_file + (o_.cert_file.empty() ? "" : ", mqtt.cert_file " + o_.cert_file));
    // The broker's certificate must be signed by the CA and name the host (no insecure mode).
    check(mosquitto_tls_opts_set(m_, 1, "tlsv1.2", nullptr), "mqtt: TLS options");
  }
  mosquitto_connect_callback_set(m_, &MqttClient::on_connect);
  mosquitto_disconnect_callback_set(m_, &MqttClient::on_disconnect);
  mosquitto_publish_callback_set(m_, &MqttClient::on_publish);
  if (o_.on_message) mosquitto_message_callback_set(m_, &MqttClient::on_message);
}

MqttClient::~MqttClient() {
  stop_ = true;
  if (thread_.joinable()) thread_.join();
  mosquitto_destroy(m_);
}

void MqttClient::start() { thread_ = std::thread([this] { run(); }); }

void MqttClient::run() {
  bool first = true;
  std::string last_failure;
  while (!stop_) {
    const int rc = first ? mosquitto_connect(m_, o_.host.c_str(), o_.port, o_.keepalive_s) : mosquitto_reconnect(m_);
    if (rc == MOSQ_ERR_SUCCESS) {
      first = false;
      int lrc = MOSQ_ERR_SUCCESS;
      while (!stop_ && (lrc = mosquitto_loop(m_, 100, 1)) == MOSQ_ERR_SUCCESS) {
      }
      connected_ = false;
      if (stop_) break;
      const std::string why = mosquitto_strerror(lrc);
      if (why != last_failure) spdlog::warn("cnc-mqtt: the connection to {}:{} ended: {}", o_.host, o_.port, why);
      last_failure = why;
    } else {
      const std::string why = mosquitto_strerror(rc);
      if (why != last_failure) spdlog::warn("cnc-mqtt: cannot connect to {}:{}: {} (retried every second)", o_.host, o_.port, why);
      last_failure = why;
    }
    for (int i = 0; i < 10 && !stop_; ++i) std::this_thread::sleep_for(std::chrono::milliseconds(100));
  }
}

void MqttClient::on_connect(mosquitto*, void* self, int rc) {
  auto* c = static_cast<MqttClient*>(self);
  if (rc != 0) {
    spdlog::error("cnc-mqtt: the broker {}:{} refused the connection: {}", c->o_.host, c->o_.port,
                  mosquitto_connack_string(rc));
    return;
  }
  for (const std::string& t : c->o_.subscribe)
    if (const int src = mosquitto_subscribe(c->m_, nullptr, t.c_str(), 1); src != MOSQ_ERR_SUCCESS)
      spdlog::error("cnc-mqtt: cannot subscribe to {}: {}", t, mosquitto_strerror(src));
  c->connected_ = true;
  ++c->connections_;
  spdlog::info("cnc-mqtt: connected to {}:{} as {}", c->o_.host, c->o_.port, c->o_.client_id);
}

void MqttClient::on_disconnect(mosquitto*, void* self, int) { static_cast<MqttClient*>(self)->connected_ = false; }

void MqttClient::on_publish(mosquitto*, void* self, int) { ++static_cast<MqttClient*>(self)->acknowledged_; }

void MqttClient::on_message(mosquitto*, void* self, const ::mosquitto_message* msg) {
  auto* c = static_cast<MqttClient*>(self);
  if (msg->topic == nullptr) return;
  // Nothing may pass through libmosquitto's C frames.
  try {
    const std::string payload = msg->payloadlen > 0 && msg->payload != nullptr
                                    ? std::string(static_cast<const char*>(msg->payload), static_cast<size_t>(msg->payloadlen))
                                    : std::string();
    c->o_.on_message(msg->topic, payload);
  } catch (const std::exception& e) {
    spdlog::warn("cnc-mqtt: a message on {} dropped: {}", msg->topic, e.what());
  }
}

bool MqttClient::publish(const Record& r) {
  const int rc = mosquitto_publish(m_, nullptr, r.topic.c_str(), static_cast<int>(r.payload.size()), r.payload.data(), 1,
                                   r.retained);
  // Not connected: libmosquitto keeps a QoS 1 message and sends it on reconnection.
  if (rc != MOSQ_ERR_SUCCESS && rc != MOSQ_ERR_NO_CONN) {
    spdlog::warn("cnc-mqtt: {} not published: {}", r.topic, mosquitto_strerror(rc));
    return false;
  }
  ++published_;
  return true;
}

void MqttClient::stop(const Record& last, double timeout_s) {
  if (connected_) {
    if (!last.topic.empty()) publish(last);
    const double until = util::monotonic_s() + timeout_s;
    while (acknowledged_ < published_ && util::monotonic_s() < until)
      std::this_thread::sleep_for(std::chrono::milliseconds(10));
    mosquitto_disconnect(m_);
  }
  stop_ = true;
  if (thread_.joinable()) thread_.join();
}

}  // namespace cnc::mqtt
