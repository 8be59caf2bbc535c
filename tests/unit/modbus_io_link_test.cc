// The link's I/O-module function codes against a real libmodbus server: coils
// (1 read, 5 write one, 15 write many), discrete inputs (2) and input registers
// (4), over a TCP socket and over an RTU line (a pseudo-terminal), with the
// exception a module gives for an address it does not have.
#include <gtest/gtest.h>
#include <modbus.h>
#include <netinet/in.h>
#include <pty.h>
#include <sys/socket.h>
#include <unistd.h>

#include <atomic>
#include <memory>
#include <thread>

#include "common/drive/modbus_link.h"

namespace cnc::drive {
namespace {

constexpr int kUnit = 5;

// A module of 16 coils, 8 discrete inputs, 4 holding and 4 input registers.
modbus_mapping_t* module_map() {
  modbus_mapping_t* m = modbus_mapping_new(16, 8, 4, 4);
  for (int i = 0; i < 8; ++i) m->tab_input_bits[i] = (i % 3 == 0) ? 1 : 0;
  for (int i = 0; i < 4; ++i) m->tab_input_registers[i] = static_cast<uint16_t>(1000 + i);
  return m;
}

// Serves requests on `ctx` until its peer goes away.
void serve(modbus_t* ctx, modbus_mapping_t* map, std::atomic<bool>& stop) {
  uint8_t q[MODBUS_RTU_MAX_ADU_LENGTH > MODBUS_TCP_MAX_ADU_LENGTH ? MODBUS_RTU_MAX_ADU_LENGTH
                                                                  : MODBUS_TCP_MAX_ADU_LENGTH];
  modbus_set_indication_timeout(ctx, 0, 100000);
  while (!stop.load()) {
    const int n = modbus_receive(ctx, q);
    if (n > 0) modbus_reply(ctx, q, n, map);
    else if (n < 0 && errno != ETIMEDOUT) break;
  }
}

void exercise(Link& link, modbus_mapping_t* map) {
  LinkCounters c;
  ASSERT_TRUE(link.ensure_open(0.0)) << link.last_error();
  // Coils: one by one and many at once, read back over FC 1 and seen in the module.
  EXPECT_EQ(link.write_coil(kUnit, 3, true, c), TxResult::kOk);
  const uint8_t many[5] = {1, 0, 1, 1, 0};
  EXPECT_EQ(link.write_coils(kUnit, 8, 5, many, c), TxResult::kOk);
  uint8_t coils[16] = {};
  EXPECT_EQ(link.read_coils(kUnit, 0, 16, coils, c), TxResult::kOk);
  for (int i = 0; i < 16; ++i) {
    const uint8_t want = i == 3 ? 1 : (i >= 8 && i < 13) ? many[i - 8] : 0;
    EXPECT_EQ(coils[i], want) << "coil " << i;
    EXPECT_EQ(map->tab_bits[i], want) << "coil " << i << " in the module";
  }
  EXPECT_EQ(link.write_coil(kUnit, 3, false, c), TxResult::kOk);
  EXPECT_EQ(map->tab_bits[3], 0);
  // Discrete inputs and input registers: the module's, not the coils or holding registers.
  uint8_t in[8] = {};
  EXPECT_EQ(link.read_discrete_inputs(kUnit, 0, 8, in, c), TxResult::kOk);
  for (int i = 0; i < 8; ++i) EXPECT_EQ(in[i], (i % 3 == 0) ? 1 : 0) << "input " << i;
  uint16_t regs[4] = {};
  EXPECT_EQ(link.read_input_registers(kUnit, 1, 3, regs, c), TxResult::kOk);
  EXPECT_EQ(regs[0], 1001);
  EXPECT_EQ(regs[2], 1003);
  // An address the module has not: an exception, counted, not fatal.
  EXPECT_EQ(link.read_coils(kUnit, 14, 4, coils, c), TxResult::kException);
  EXPECT_EQ(link.read_input_registers(kUnit, 4, 1, regs, c), TxResult::kException);
  EXPECT_EQ(c.exceptions, 2);
  EXPECT_EQ(c.transactions, 8);
  EXPECT_TRUE(link.is_open());
  EXPECT_EQ(link.read_discrete_inputs(kUnit, 0, 1, in, c), TxResult::kOk);
}

TEST(ModbusIoLink, CoilsDiscreteInputsAndInputRegistersOverTcp) {
  modbus_mapping_t* map = module_map();
  modbus_t* server = modbus_new_tcp("127.0.0.1", 0);
  ASSERT_NE(server, nullptr);
  const int listen_fd = modbus_tcp_listen(server, 1);
  ASSERT_GE(listen_fd, 0);
  sockaddr_in sa{};
  socklen_t len = sizeof sa;
  ASSERT_EQ(getsockname(listen_fd, reinterpret_cast<sockaddr*>(&sa), &len), 0);
  const int port = ntohs(sa.sin_port);
  std::atomic<bool> stop{false};
  std::thread t([&] {
    int fd = listen_fd;
    if (modbus_tcp_accept(server, &fd) >= 0) serve(server, map, stop);
  });
  {
    auto link = ModbusLink::tcp("127.0.0.1", port, 0.5);
    exercise(*link, map);
  }  // the link closes: the server's receive ends
  stop = true;
  t.join();
  close(listen_fd);
  modbus_close(server);
  modbus_free(server);
  modbus_mapping_free(map);
}

TEST(ModbusIoLink, CoilsDiscreteInputsAndInputRegistersOverRtu) {
  int master = -1, slave = -1;
  char name[256] = {};
  ASSERT_EQ(openpty(&master, &slave, name, nullptr, nullptr), 0);
  modbus_mapping_t* map = module_map();
  // The module's end of the line is the pseudo-terminal's master side.
  modbus_t* server = modbus_new_rtu("/dev/null", 115200, 'N', 8, 1);
  ASSERT_NE(server, nullptr);
  modbus_set_slave(server, kUnit);
  modbus_set_socket(server, master);
  std::atomic<bool> stop{false};
  std::thread t([&] { serve(server, map, stop); });
  {
    auto link = ModbusLink::rtu(name, 115200, 'N', 1, 0.5);
    exercise(*link, map);
  }
  stop = true;
  t.join();
  modbus_set_socket(server, -1);
  modbus_free(server);
  close(master);
  close(slave);
  modbus_mapping_free(map);
}

}  // namespace
}  // namespace cnc::drive
