/*
 * The codec's fast path, for Dolphin.MAVLink.Native (see there for how the
 * parser uses it): runs of well-formed MAVLink frames checked and decoded in
 * one call.
 *
 * Why C: per frame, the Elixir decoder's time went to the checksum call, to
 * reading each float (a runtime call each), and to the two structs; the
 * MAVLink C library decoded the benchmark's telemetry 1.7 times faster. Here
 * one call takes every frame of a buffer that is complete, unsigned, of a
 * message the dialect defines and whose checksum holds, decodes its fields
 * into the terms the Elixir decoder makes of them (integers, floats, NaN and
 * infinities as atoms, strings cut at their NUL, arrays as lists), and
 * stops at the first frame that is anything else: the Elixir
 * parser takes that one (resynchronisation, signing, unknown ids, counting
 * what it drops) and calls again after it. So everything but the fast path
 * stays in one place, and the terms never differ (a property test decodes
 * random streams both ways). The structs are built in Elixir, from a tuple
 * per frame: a map built here through the NIF API takes a key tuple and a
 * sort of its keys of its own, which cost more than all the decoding.
 *
 * A call decodes at most MAX_FRAMES frames (each a few hundred bytes at most:
 * well under a millisecond); the table of messages is built once per dialect
 * (table/1) and kept as a resource. Every offset is checked against the
 * binary: nothing is read outside it.
 */
#include <erl_nif.h>
#include <stdint.h>
#include <stdlib.h>
#include <string.h>

#include "crc16.h"

#define MAX_FRAMES 512
#define MAGIC_V2 0xFD
#define MAGIC_V1 0xFE

enum { T_CHAR, T_UINT8, T_INT8, T_UINT16, T_INT16, T_UINT32, T_INT32, T_UINT64, T_INT64, T_FLOAT, T_DOUBLE, T_COUNT };
static const unsigned type_size[T_COUNT] = {1, 1, 1, 2, 2, 4, 4, 8, 8, 4, 8};

typedef struct {
  unsigned offset; /* in the payload */
  unsigned type;
  unsigned count; /* array length; 0: a scalar */
} field_t;

typedef struct {
  uint32_t id;
  unsigned crc_extra;
  unsigned max_len;
  unsigned nfields;
  ERL_NIF_TERM module; /* an atom: global, never collected */
  field_t *fields;     /* in the order of the message's definition */
} message_t;

typedef struct {
  size_t n;
  message_t *messages; /* sorted by id */
} table_t;

static ErlNifResourceType *table_type;

static ERL_NIF_TERM atom_nan, atom_infinity, atom_neg_infinity;

static void table_free(ErlNifEnv *env, void *obj) {
  table_t *t = obj;
  (void)env;
  for (size_t i = 0; i < t->n; i++) {
    free(t->messages[i].fields);
  }
  free(t->messages);
}

static int load(ErlNifEnv *env, void **priv_data, ERL_NIF_TERM load_info) {
  (void)priv_data;
  (void)load_info;
  crc16_init();
  table_type = enif_open_resource_type(env, NULL, "dolphin_native_table", table_free, ERL_NIF_RT_CREATE, NULL);
  if (table_type == NULL) return 1;
  atom_nan = enif_make_atom(env, "nan");
  atom_infinity = enif_make_atom(env, "infinity");
  atom_neg_infinity = enif_make_atom(env, "neg_infinity");
  return 0;
}

static int by_id(const void *a, const void *b) {
  uint32_t x = ((const message_t *)a)->id, y = ((const message_t *)b)->id;
  return (x > y) - (x < y);
}

/* One message of table/1's list: {Id, CrcExtra, MaxLen, Module, [{Type, Count, Offset}]}. */
static int read_message(ErlNifEnv *env, ERL_NIF_TERM spec, message_t *m) {
  const ERL_NIF_TERM *tuple;
  int arity;
  unsigned id, crc_extra, max_len, nfields;
  ERL_NIF_TERM list, head;

  if (!enif_get_tuple(env, spec, &arity, &tuple) || arity != 5 || !enif_get_uint(env, tuple[0], &id) || id > 0xFFFFFF ||
      !enif_get_uint(env, tuple[1], &crc_extra) || crc_extra > 255 || !enif_get_uint(env, tuple[2], &max_len) || max_len > 255 ||
      !enif_is_atom(env, tuple[3]) || !enif_get_list_length(env, tuple[4], &nfields) || nfields > 255)
    return 0;

  m->id = id;
  m->crc_extra = crc_extra;
  m->max_len = max_len;
  m->module = tuple[3];
  m->nfields = nfields;
  m->fields = calloc(nfields ? nfields : 1, sizeof(field_t));
  if (m->fields == NULL) return 0;

  list = tuple[4];
  for (unsigned i = 0; enif_get_list_cell(env, list, &head, &list); i++) {
    const ERL_NIF_TERM *f;
    unsigned type, count, offset;
    if (!enif_get_tuple(env, head, &arity, &f) || arity != 3 || !enif_get_uint(env, f[0], &type) || type >= T_COUNT ||
        !enif_get_uint(env, f[1], &count) || !enif_get_uint(env, f[2], &offset) || offset + type_size[type] * (count ? count : 1) > max_len)
      return 0;
    m->fields[i] = (field_t){offset, type, count};
  }
  return 1;
}

/* table(Messages): the resource decode/4 reads its messages from. */
static ERL_NIF_TERM table(ErlNifEnv *env, int argc, const ERL_NIF_TERM argv[]) {
  unsigned n;
  ERL_NIF_TERM list = argv[0], head;
  (void)argc;
  if (!enif_get_list_length(env, list, &n)) return enif_make_badarg(env);

  table_t *t = enif_alloc_resource(table_type, sizeof(table_t));
  t->n = 0;
  t->messages = calloc(n ? n : 1, sizeof(message_t));
  ERL_NIF_TERM result = enif_make_resource(env, t);
  enif_release_resource(t);
  if (t->messages == NULL) return enif_make_badarg(env);

  while (enif_get_list_cell(env, list, &head, &list)) {
    /* Counted before it is read: table_free frees what a bad entry allocated. */
    message_t *m = &t->messages[t->n++];
    if (!read_message(env, head, m)) return enif_make_badarg(env);
  }
  qsort(t->messages, t->n, sizeof(message_t), by_id);
  return result;
}

static const message_t *lookup(const table_t *t, uint32_t id) {
  size_t lo = 0, hi = t->n;
  while (lo < hi) {
    size_t mid = (lo + hi) / 2;
    uint32_t at = t->messages[mid].id;
    if (at == id) return &t->messages[mid];
    if (at < id) lo = mid + 1;
    else hi = mid;
  }
  return NULL;
}

static uint64_t read_le(const unsigned char *p, unsigned size) {
  uint64_t v = 0;
  for (unsigned i = 0; i < size; i++) v |= (uint64_t)p[i] << (8 * i);
  return v;
}

/* A float's bits as Dolphin.MAVLink.Value decodes them: a number, or for
 * NaN and the infinities (which BEAM floats cannot hold) an atom, or
 * {:nan, bits} for a NaN other than the quiet one. */
static ERL_NIF_TERM special(ErlNifEnv *env, uint64_t bits, uint64_t inf, uint64_t quiet_nan, unsigned sign_bit) {
  if (bits == inf) return atom_infinity;
  if (bits == (inf | (1ULL << sign_bit))) return atom_neg_infinity;
  if (bits == quiet_nan) return atom_nan;
  return enif_make_tuple2(env, atom_nan, enif_make_uint64(env, bits));
}

static ERL_NIF_TERM scalar(ErlNifEnv *env, const unsigned char *p, unsigned type) {
  switch (type) {
  case T_UINT8: return enif_make_uint(env, p[0]);
  case T_INT8: return enif_make_int(env, (int8_t)p[0]);
  case T_UINT16: return enif_make_uint(env, (uint16_t)read_le(p, 2));
  case T_INT16: return enif_make_int(env, (int16_t)read_le(p, 2));
  case T_UINT32: return enif_make_uint(env, (uint32_t)read_le(p, 4));
  case T_INT32: return enif_make_int(env, (int32_t)read_le(p, 4));
  case T_UINT64: return enif_make_uint64(env, read_le(p, 8));
  case T_INT64: return enif_make_int64(env, (int64_t)read_le(p, 8));
  case T_FLOAT: {
    uint32_t bits = (uint32_t)read_le(p, 4);
    float f;
    if ((bits & 0x7F800000u) == 0x7F800000u) return special(env, bits, 0x7F800000u, 0x7FC00000u, 31);
    memcpy(&f, &bits, sizeof f);
    return enif_make_double(env, (double)f);
  }
  default: { /* T_DOUBLE */
    uint64_t bits = read_le(p, 8);
    double d;
    if ((bits & 0x7FF0000000000000ull) == 0x7FF0000000000000ull) return special(env, bits, 0x7FF0000000000000ull, 0x7FF8000000000000ull, 63);
    memcpy(&d, &bits, sizeof d);
    return enif_make_double(env, d);
  }
  }
}

/* One field's value. `source` is the binary the payload `p` lies in, and
 * `base` the payload's offset there (or -1 when `p` is a zero-filled copy):
 * a string is then a sub-binary of it, as the Elixir decoder makes it. */
static ERL_NIF_TERM field(ErlNifEnv *env, ERL_NIF_TERM source, long base, const unsigned char *p, const field_t *f) {
  const unsigned char *at = p + f->offset;
  if (f->type == T_CHAR) {
    unsigned n = f->count ? f->count : 1;
    const unsigned char *nul = memchr(at, 0, n);
    size_t len = nul ? (size_t)(nul - at) : n;
    if (base >= 0) return enif_make_sub_binary(env, source, (size_t)base + f->offset, len);
    ERL_NIF_TERM bin;
    unsigned char *out = enif_make_new_binary(env, len, &bin);
    memcpy(out, at, len);
    return bin;
  }
  if (f->count == 0) return scalar(env, at, f->type);
  ERL_NIF_TERM list = enif_make_list(env, 0);
  unsigned size = type_size[f->type];
  for (unsigned i = f->count; i > 0; i--) list = enif_make_list_cell(env, scalar(env, at + (i - 1) * size, f->type), list);
  return list;
}

/* native_decode(Binary, Offset, Table): decodes the frames from Offset on while
 * each is whole, unsigned, of a message of Table, with a good checksum (at
 * most MAX_FRAMES). Returns {Frames, NextOffset}, Frames in order, each
 * {Module, Values, Version, SysId, CompId, Seq, MsgId, CompatFlags, Payload,
 * Raw}: Values the tuple of the message's fields in the order of its
 * definition, Payload and Raw sub-binaries of Binary. */
static ERL_NIF_TERM decode(ErlNifEnv *env, int argc, const ERL_NIF_TERM argv[]) {
  ErlNifBinary bin;
  unsigned at;
  table_t *t;
  (void)argc;
  if (!enif_inspect_binary(env, argv[0], &bin) || !enif_get_uint(env, argv[1], &at) || at > bin.size ||
      !enif_get_resource(env, argv[2], table_type, (void **)&t))
    return enif_make_badarg(env);

  const unsigned char *d = bin.data;
  size_t pos = at;
  unsigned count = 0;
  ERL_NIF_TERM frames = enif_make_list(env, 0);
  ERL_NIF_TERM values[256];
  unsigned char zero_filled[256];

  while (count < MAX_FRAMES) {
    size_t left = bin.size - pos, size, payload_at, header;
    unsigned len, version, compat, seq, sysid, compid;
    uint32_t msgid;

    if (left >= 12 && d[pos] == MAGIC_V2 && d[pos + 2] == 0) {
      len = d[pos + 1];
      size = 12 + (size_t)len;
      if (left < size) break;
      version = 2;
      compat = d[pos + 3];
      seq = d[pos + 4];
      sysid = d[pos + 5];
      compid = d[pos + 6];
      msgid = (uint32_t)d[pos + 7] | (uint32_t)d[pos + 8] << 8 | (uint32_t)d[pos + 9] << 16;
      header = 9;
      payload_at = pos + 10;
    } else if (left >= 8 && d[pos] == MAGIC_V1) {
      len = d[pos + 1];
      size = 8 + (size_t)len;
      if (left < size) break;
      version = 1;
      compat = 0;
      seq = d[pos + 2];
      sysid = d[pos + 3];
      compid = d[pos + 4];
      msgid = d[pos + 5];
      header = 5;
      payload_at = pos + 6;
    } else {
      break;
    }

    const message_t *m = lookup(t, msgid);
    if (m == NULL) break;
    uint16_t crc = crc16_accumulate_byte(crc16_accumulate(0xFFFF, d + pos + 1, header + len), m->crc_extra);
    if (crc != (uint16_t)(d[payload_at + len] | d[payload_at + len + 1] << 8)) break;

    /* A payload shorter than the message (MAVLink 2 truncation, a MAVLink 1
     * frame without the extensions) reads as zero-filled; a longer one is
     * read up to the message's length. */
    const unsigned char *p = d + payload_at;
    long base = (long)payload_at;
    if (len < m->max_len) {
      memcpy(zero_filled, p, len);
      memset(zero_filled + len, 0, m->max_len - len);
      p = zero_filled;
      base = -1;
    }

    for (unsigned i = 0; i < m->nfields; i++) values[i] = field(env, argv[0], base, p, &m->fields[i]);
    ERL_NIF_TERM frame[10] = {
        m->module,
        enif_make_tuple_from_array(env, values, m->nfields),
        enif_make_uint(env, version),
        enif_make_uint(env, sysid),
        enif_make_uint(env, compid),
        enif_make_uint(env, seq),
        enif_make_uint(env, msgid),
        enif_make_uint(env, compat),
        enif_make_sub_binary(env, argv[0], payload_at, len),
        enif_make_sub_binary(env, argv[0], pos, size),
    };
    frames = enif_make_list_cell(env, enif_make_tuple_from_array(env, frame, 10), frames);
    pos += size;
    count++;
  }
  ERL_NIF_TERM in_order;
  enif_make_reverse_list(env, frames, &in_order);
  return enif_make_tuple2(env, in_order, enif_make_uint64(env, pos));
}

static ErlNifFunc functions[] = {
    {"table", 1, table, 0},
    {"native_decode", 3, decode, 0},
};

ERL_NIF_INIT(Elixir.Dolphin.MAVLink.Native, functions, load, NULL, NULL, NULL)
