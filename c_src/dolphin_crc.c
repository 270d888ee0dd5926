/*
 * The MAVLink checksum (CRC-16/MCRF4XX, "X.25" in MAVLink's sources) for
 * Dolphin.MAVLink.CRC, which falls back to its Erlang implementation when this
 * library cannot be loaded.
 *
 * Why C: a table-driven CRC is a chain of dependent table look-ups. In Erlang
 * each look-up is several checked operations, and the 65,536-entry table that
 * keeps their number down does not stay in the processor's caches on a busy
 * machine; that made the checksum half of the time spent per frame. Here eight
 * 256-entry tables (4 KiB) take eight bytes per step ("slicing by 8"), with
 * independent look-ups.
 *
 * Each call reads at most 280 bytes (a MAVLink frame): far below what a
 * normal scheduler may spend in a NIF. Every offset and length is checked
 * against the binary, so bad arguments raise badarg and never read outside it.
 */
#include <erl_nif.h>
#include <stdint.h>
#include <string.h>

#include "crc16.h"

static int load(ErlNifEnv *env, void **priv_data, ERL_NIF_TERM load_info) {
  (void)env; (void)priv_data; (void)load_info;
  crc16_init();
  return 0;
}

/* checksum(Binary, Offset, Length, CrcExtra): the CRC from 0xFFFF over Length
 * bytes of Binary from Offset, then the CrcExtra byte. */
static ERL_NIF_TERM checksum(ErlNifEnv *env, int argc, const ERL_NIF_TERM argv[]) {
  ErlNifBinary bin;
  unsigned offset, length, extra;
  (void)argc;
  if (!enif_inspect_binary(env, argv[0], &bin) || !enif_get_uint(env, argv[1], &offset) ||
      !enif_get_uint(env, argv[2], &length) || !enif_get_uint(env, argv[3], &extra) || extra > 255 ||
      (size_t)offset + length > bin.size)
    return enif_make_badarg(env);
  return enif_make_uint(env, crc16_accumulate_byte(crc16_accumulate(0xFFFF, bin.data + offset, length), extra));
}

/* frame_checksum(Header, MsgId, Payload, Length, CrcExtra): the checksum of a
 * MAVLink 2 frame whose first seven bytes are the little-endian integer Header
 * (magic, len, flags, compat, seq, sysid, compid: the magic is not checksummed),
 * with the 24-bit MsgId and the first Length bytes of Payload. */
static ERL_NIF_TERM frame_checksum(ErlNifEnv *env, int argc, const ERL_NIF_TERM argv[]) {
  ErlNifUInt64 header;
  unsigned msgid, length, extra;
  ErlNifBinary payload;
  unsigned char head[9];
  (void)argc;
  if (!enif_get_uint64(env, argv[0], &header) || !enif_get_uint(env, argv[1], &msgid) || msgid > 0xFFFFFF ||
      !enif_inspect_binary(env, argv[2], &payload) || !enif_get_uint(env, argv[3], &length) ||
      !enif_get_uint(env, argv[4], &extra) || extra > 255 || length > payload.size)
    return enif_make_badarg(env);
  for (int i = 0; i < 6; i++) head[i] = (unsigned char)(header >> (8 * (i + 1)));
  for (int i = 0; i < 3; i++) head[6 + i] = (unsigned char)(msgid >> (8 * i));
  uint16_t crc = crc16_accumulate(crc16_accumulate(0xFFFF, head, sizeof head), payload.data, length);
  return enif_make_uint(env, crc16_accumulate_byte(crc, extra));
}

/* frame_v2(Header, MsgId, Payload, CrcExtra): the MAVLink 2 frame of a whole
 * Payload (its message's full length): its trailing zero bytes dropped (one
 * kept at least), the length put into Header (the frame's first seven bytes
 * as a little-endian integer whose length byte is 0), then MsgId, the
 * payload kept and the checksum, in one new binary. */
static ERL_NIF_TERM frame_v2(ErlNifEnv *env, int argc, const ERL_NIF_TERM argv[]) {
  ErlNifUInt64 header;
  unsigned msgid, extra;
  ErlNifBinary payload;
  ERL_NIF_TERM frame;
  (void)argc;
  if (!enif_get_uint64(env, argv[0], &header) || (header & 0xFF00) != 0 || header > 0xFFFFFFFFFFFFFFull ||
      !enif_get_uint(env, argv[1], &msgid) || msgid > 0xFFFFFF || !enif_inspect_binary(env, argv[2], &payload) ||
      payload.size == 0 || payload.size > 255 || !enif_get_uint(env, argv[3], &extra) || extra > 255)
    return enif_make_badarg(env);
  size_t len = payload.size;
  while (len > 1 && payload.data[len - 1] == 0) len--;
  header |= (ErlNifUInt64)len << 8;
  unsigned char *out = enif_make_new_binary(env, 12 + len, &frame);
  if (out == NULL) return enif_make_badarg(env);
  for (int i = 0; i < 7; i++) out[i] = (unsigned char)(header >> (8 * i));
  for (int i = 0; i < 3; i++) out[7 + i] = (unsigned char)(msgid >> (8 * i));
  memcpy(out + 10, payload.data, len);
  uint16_t crc = crc16_accumulate_byte(crc16_accumulate(0xFFFF, out + 1, 9 + len), extra);
  out[10 + len] = (unsigned char)(crc & 0xFF);
  out[11 + len] = (unsigned char)(crc >> 8);
  return frame;
}

static ERL_NIF_TERM implementation(ErlNifEnv *env, int argc, const ERL_NIF_TERM argv[]) {
  (void)argc; (void)argv;
  return enif_make_atom(env, "native");
}

static ErlNifFunc functions[] = {
    {"implementation", 0, implementation, 0},
    {"checksum", 4, checksum, 0},
    {"frame_checksum", 5, frame_checksum, 0},
    {"frame_v2", 4, frame_v2, 0},
};

ERL_NIF_INIT(Elixir.Dolphin.MAVLink.CRC, functions, load, NULL, NULL, NULL)
