#pragma once
// The broker connection of cnc-mqtt (libmosquitto): MQTT 3.1.1, QoS 1, a persistent
// session under a fixed client id (clean_session false), the last will, TLS and a
// user name and password. One thread of its own connects, reconnects (every second
// while the broker is away) and moves the packets; publish() may be called from any
// thread. QoS 1 records published while the broker is away are kept by libmosquitto
// and sent when the connection is back.
#include <atomic>
#include <cstdint>
#include <functional>
#include <string>
#include <thread>
#include <vector>

#include "services/mqtt/fleet_reporter.h"

struct mosquitto;
struct mosquitto_message;

namespace cnc::mqtt {

struct ClientOptions {
  std::string host;
  int port = 1883;
  std::string client_id;
  int keepalive_s = 10;
  std::string username, password;
  std::string ca_file, cert_file, key_file;  // ca_file "": no TLS
  Record will;                 // topic "": none
  bool clean_session = false;  // false: the broker keeps the session (a cell's records)
  // A reader's (cnc-fleet's) topics, subscribed at QoS 1 at every connection, and what
  // it is handed (in the client's thread). A cell's cnc-mqtt subscribes to nothing.
  std::vector<std::string> subscribe;
  std::function<void(const std::string& topic, const std::string& payload)> on_message;
};

class MqttClient {
 public:
  // Throws std::runtime_error naming what libmosquitto refused (a TLS file, ...).
  explicit MqttClient(const ClientOptions& o);
  ~MqttClient();
  MqttClient(const MqttClient&) = delete;
  MqttClient& operator=(const MqttClient&) = delete;

  void start();
  // QoS 1. False when libmosquitto refused it (not queued).
  bool publish(const Record& r);
  bool connected() const { return connected_.load(); }
  // Connections the broker accepted so far: a change means a (re)connection.
  int64_t connections() const { return connections_.load(); }
  int64_t published() const { return published_.load(); }
  int64_t acknowledged() const { return acknowledged_.load(); }
  // Publishes `last`, waits up to timeout_s for every record to be acknowledged,
  // then disconnects cleanly (the broker does not send the will).
  void stop(const Record& last, double timeout_s);

 private:
  void run();
  static void on_connect(mosquitto* m, void* self, int rc);
  static void on_disconnect(mosquitto* m, void* self, int rc);
  static void on_publish(mosquitto* m, void* self, int mid);
  static void on_message(mosquitto* m, void* self, const ::mosquitto_message* msg);

  ClientOptions o_;
  mosquitto* m_ = nullptr;
  std::thread thread_;
  std::atomic<bool> stop_{false}, connected_{false};
  std::atomic<int64_t> connections_{0}, published_{0}, acknowledged_{0};
};

}  // namespace cnc::mqtt
