/*
 * The MAVLink C library's decode and encode speed on a file of MAVLink
 * frames, for bench/codec.exs to set beside ours in the same run.
 *
 * Built by bench/codec.exs against headers generated from the dialect by the
 * pinned pymavlink's mavgen (and the switch of bench/peers/make_c_switch.py):
 *
 *   decode: every byte of the file through mavlink_parse_char (the library's
 *           parser, checksums checked), every frame decoded into its message
 *           struct (mavlink_msg_<name>_decode), kept with its header;
 *   encode: every decoded message encoded again with its header
 *           (mavlink_msg_<name>_encode_chan, the sequence number of the
 *           channel set to the frame's) and written out
 *           (mavlink_msg_to_send_buffer); the bytes must be the file's.
 *
 * Prints one line: frames=N decode_ns=D encode_ns=E decode_cpu_ns=DC
 * encode_cpu_ns=EC identical=yes|no errors=K: nanoseconds per frame, the best
 * of ROUNDS rounds, of wall-clock time and of the process's CPU time.
 *
 * Usage: mavlink_c FILE [ROUNDS]
 */
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <time.h>

#include "ardupilotmega/mavlink.h"
#include "peer_switch.h"

union peer_message {
  PEER_UNION_MEMBERS
};

struct decoded {
  uint32_t msgid;
  uint8_t sysid, compid, seq;
  union peer_message m;
};

static void decode_any(const mavlink_message_t *msg, union peer_message *out) {
  switch (msg->msgid) {
    PEER_DECODE_CASES
    default: break;
  }
}

static void encode_any(uint32_t msgid, uint8_t sysid, uint8_t compid, uint8_t chan, mavlink_message_t *msg, const union peer_message *in) {
  switch (msgid) {
    PEER_ENCODE_CASES
    default: break;
  }
}

static double ns(clockid_t clock) {
  struct timespec t;
  clock_gettime(clock, &t);
  return t.tv_sec * 1e9 + t.tv_nsec;
}

static size_t decode_all(const uint8_t *bytes, size_t len, struct decoded *out, unsigned *errors) {
  mavlink_status_t status;
  mavlink_message_t msg;
  size_t n = 0;

  memset(mavlink_get_channel_status(MAVLINK_COMM_0), 0, sizeof(mavlink_status_t));
  memset(mavlink_get_channel_buffer(MAVLINK_COMM_0), 0, sizeof(mavlink_message_t));
  for (size_t i = 0; i < len; i++) {
    if (mavlink_parse_char(MAVLINK_COMM_0, bytes[i], &msg, &status)) {
      struct decoded *d = &out[n++];
      d->msgid = msg.msgid;
      d->sysid = msg.sysid;
      d->compid = msg.compid;
      d->seq = msg.seq;
      decode_any(&msg, &d->m);
    }
  }
  *errors = status.parse_error + status.packet_rx_drop_count;
  return n;
}

static size_t encode_all(const struct decoded *in, size_t n, uint8_t *out) {
  mavlink_status_t *status = mavlink_get_channel_status(MAVLINK_COMM_1);
  mavlink_message_t msg;
  size_t pos = 0;

  for (size_t i = 0; i < n; i++) {
    status->current_tx_seq = in[i].seq;
    status->flags = 0;
    encode_any(in[i].msgid, in[i].sysid, in[i].compid, MAVLINK_COMM_1, &msg, &in[i].m);
    pos += mavlink_msg_to_send_buffer(out + pos, &msg);
  }
  return pos;
}

int main(int argc, char **argv) {
  if (argc < 2) {
    fprintf(stderr, "usage: %s FILE [ROUNDS]\n", argv[0]);
    return 2;
  }
  int rounds = argc > 2 ? atoi(argv[2]) : 9;

  FILE *f = fopen(argv[1], "rb");
  if (!f) {
    perror(argv[1]);
    return 1;
  }
  fseek(f, 0, SEEK_END);
  size_t len = ftell(f);
  fseek(f, 0, SEEK_SET);
  uint8_t *bytes = malloc(len);
  if (fread(bytes, 1, len, f) != len) {
    perror(argv[1]);
    return 1;
  }
  fclose(f);

  /* At most one frame per 12 bytes (the shortest MAVLink 2 frame). */
  struct decoded *frames = calloc(len / 12 + 1, sizeof(struct decoded));
  uint8_t *encoded = malloc(len + MAVLINK_MAX_PACKET_LEN);
  double best_decode = 1e300, best_encode = 1e300, best_decode_cpu = 1e300, best_encode_cpu = 1e300;
  size_t n = 0, size = 0;
  unsigned errors = 0;

  for (int r = 0; r < rounds; r++) {
    double t0 = ns(CLOCK_MONOTONIC), c0 = ns(CLOCK_PROCESS_CPUTIME_ID);
    n = decode_all(bytes, len, frames, &errors);
    double t1 = ns(CLOCK_MONOTONIC), c1 = ns(CLOCK_PROCESS_CPUTIME_ID);
    size = encode_all(frames, n, encoded);
    double t2 = ns(CLOCK_MONOTONIC), c2 = ns(CLOCK_PROCESS_CPUTIME_ID);
    if (t1 - t0 < best_decode) best_decode = t1 - t0;
    if (t2 - t1 < best_encode) best_encode = t2 - t1;
    if (c1 - c0 < best_decode_cpu) best_decode_cpu = c1 - c0;
    if (c2 - c1 < best_encode_cpu) best_encode_cpu = c2 - c1;
  }

  int identical = size == len && memcmp(bytes, encoded, len) == 0;
  printf("frames=%zu decode_ns=%.1f encode_ns=%.1f decode_cpu_ns=%.1f encode_cpu_ns=%.1f identical=%s errors=%u\n", n, best_decode / n, best_encode / n,
         best_decode_cpu / n, best_encode_cpu / n, identical ? "yes" : "no", errors);
  return 0;
}
