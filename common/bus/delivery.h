#pragma once
// Who stalled: the publishers or the delivery between them? A log holds, for every
// message, the publisher's wall-clock stamp (`utime`, taken just before the send)
// and the logger's receive stamp (the kernel's SO_TIMESTAMP). A silence on the
// receive side during which publishers went on stamping messages, which then
// arrive together, is a stall of the delivery (the host's network stack or the
// receivers' scheduling), not of a publisher; a periodic channel whose own stamps
// stop is a stall of its publisher. A watchdog that trips ("no setpoint for 51 ms")
// cannot tell the two apart; the log can.
#include <cstdint>
#include <string>
#include <vector>

namespace cnc::bus {

struct DeliveryEvent {
  std::string channel;
  int32_t sender = 0;
  int64_t published_us = 0;  // the message's utime
  int64_t received_us = 0;   // the log's receive stamp
};

struct ChannelDelivery {
  std::string channel;
  int64_t events = 0;
  double p50_ms = 0, p999_ms = 0, max_ms = 0;  // received - published
  // Periodic channels (median interval under a quarter of the threshold): the
  // longest interval between two messages of one sender, by their own stamps.
  bool periodic = false;
  double longest_publish_gap_ms = 0;
  int64_t longest_publish_gap_at_us = 0;  // the stamp of the message before it
};

struct DeliveryStall {
  int64_t from_us = 0;        // the last receive stamp before the silence
  double length_ms = 0;       // the silence on the receive side
  int64_t published_in = 0;   // messages stamped inside it (they arrived after it)
  int senders_in = 0;         // distinct senders of those
  // The periodic channels' longest publish gaps inside the silence ("" when none).
  std::string publisher_gaps;
  bool delivery = false;  // messages were published inside the silence: the delivery stalled
};

struct DeliveryReport {
  std::vector<ChannelDelivery> channels;
  std::vector<DeliveryStall> stalls;  // receive-side silences over the threshold
};

// events in log order (by receive stamp); stall_ms: the silence that counts.
DeliveryReport analyse_delivery(std::vector<DeliveryEvent> events, double stall_ms);

// The report as text: a table per channel and a line per stall, with its verdict.
// t0_us: the origin of the times printed (the log's first receive stamp).
std::string format_delivery(const DeliveryReport& r, int64_t t0_us, double stall_ms);

}  // namespace cnc::bus
