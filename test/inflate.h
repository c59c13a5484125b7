/* An independent inflate (RFC 1950/1951) for the tests of rrv's PNG and EXR
   writers. It decodes Huffman codes bit by bit, counting codes of each
   length (the canonical order), which is slow and obviously right, and it
   shares no code or tables with rrv.h. */
#ifndef RRV_TEST_INFLATE_H
#define RRV_TEST_INFLATE_H

#include <stdint.h>
#include <string.h>

typedef struct inflate_state {
    const unsigned char *in;
    size_t in_size, in_pos;
    unsigned bit_buffer, bit_count;
    unsigned char *out;
    size_t out_size, out_pos;
    int error;
} inflate_state;

static unsigned take_bits(inflate_state *s, unsigned n)
{
    unsigned value = 0, i;
    for (i = 0; i < n; ++i) {
        if (s->bit_count == 0) {
            if (s->in_pos >= s->in_size) { s->error = 1; return 0; }
            s->bit_buffer = s->in[s->in_pos++];
            s->bit_count = 8;
        }
        value |= (s->bit_buffer & 1u) << i;
        s->bit_buffer >>= 1;
        --s->bit_count;
    }
    return value;
}

typedef struct huffman_table {
    short count[16];
    short symbol[320];
} huffman_table;

/* Returns 0 unless the lengths form a complete or a single-code prefix code. */
static int build_table(huffman_table *t, const unsigned char *lengths, int n)
{
    short offset[16];
    int i, left = 1;
    memset(t->count, 0, sizeof t->count);
    for (i = 0; i < n; ++i) ++t->count[lengths[i]];
    for (i = 1; i < 16; ++i) {
        left = left * 2 - t->count[i];
        if (left < 0) return 0; /* over-subscribed */
    }
    offset[1] = 0;
    for (i = 1; i < 15; ++i) offset[i + 1] = (short)(offset[i] + t->count[i]);
    for (i = 0; i < n; ++i)
        if (lengths[i]) t->symbol[offset[lengths[i]]++] = (short)i;
    return left == 0; /* rrv promises complete codes */
}

static int decode_symbol(inflate_state *s, const huffman_table *t)
{
    int code = 0, first = 0, index = 0, length;
    for (length = 1; length < 16; ++length) {
        int count = t->count[length];
        code |= (int)take_bits(s, 1);
        if (s->error) return -1;
        if (code - count < first) return t->symbol[index + (code - first)];
        index += count;
        first = (first + count) << 1;
        code <<= 1;
    }
    s->error = 1;
    return -1;
}

static const short length_base[29] = { 3, 4, 5, 6, 7, 8, 9, 10, 11, 13, 15, 17, 19, 23, 27, 31, 35,
                                        43, 51, 59, 67, 83, 99, 115, 131, 163, 195, 227, 258 };
static const short length_bits[29] = { 0, 0, 0, 0, 0, 0, 0, 0, 1, 1, 1, 1, 2, 2, 2,
                                       2, 3, 3, 3, 3, 4, 4, 4, 4, 5, 5, 5, 5, 0 };
static const short dist_base[30] = { 1, 2, 3, 4, 5, 7, 9, 13, 17, 25, 33, 49, 65, 97, 129,
                                     193, 257, 385, 513, 769, 1025, 1537, 2049, 3073, 4097,
                                     6145, 8193, 12289, 16385, 24577 };
static const short dist_bits[30] = { 0, 0, 0, 0, 1, 1, 2, 2, 3, 3, 4, 4, 5, 5, 6,
                                     6, 7, 7, 8, 8, 9, 9, 10, 10, 11, 11, 12, 12, 13, 13 };

static int inflate_codes(inflate_state *s, const huffman_table *lit, const huffman_table *dist)
{
    for (;;) {
        int symbol = decode_symbol(s, lit);
        if (s->error) return 0;
        if (symbol < 256) {
            if (s->out_pos >= s->out_size) return 0;
            s->out[s->out_pos++] = (unsigned char)symbol;
        } else if (symbol == 256) {
            return 1;
        } else {
            int length, d;
            size_t distance;
            symbol -= 257;
            if (symbol >= 29) return 0;
            length = length_base[symbol] + (int)take_bits(s, (unsigned)length_bits[symbol]);
            d = decode_symbol(s, dist);
            if (s->error || d < 0 || d >= 30) return 0;
            distance = (size_t)dist_base[d] + take_bits(s, (unsigned)dist_bits[d]);
            if (s->error || distance > s->out_pos || distance > 32768) return 0;
            if (s->out_pos + (size_t)length > s->out_size) return 0;
            for (; length > 0; --length, ++s->out_pos) s->out[s->out_pos] = s->out[s->out_pos - distance];
        }
    }
}

/* Inflates a whole zlib stream; returns the bytes produced or (size_t)-1.
   block_types, when not NULL, counts the blocks of each BTYPE: [0] stored,
   [1] fixed Huffman, [2] dynamic Huffman. */
static size_t zlib_inflate_blocks(const unsigned char *in, size_t in_size, unsigned char *out, size_t out_size,
                                  int block_types[3])
{
    static const unsigned char order[19] = { 16, 17, 18, 0, 8, 7, 9, 6, 10, 5, 11, 4, 12, 3, 13, 2, 14, 1, 15 };
    inflate_state s;
    int last;
    uint32_t a = 1, b = 0, want;
    size_t i;
    if (in_size < 6 || (in[0] & 15) != 8 || ((unsigned)in[0] << 8 | in[1]) % 31 != 0 || (in[1] & 32)) return (size_t)-1;
    memset(&s, 0, sizeof s);
    s.in = in + 2;
    s.in_size = in_size - 6;
    s.out = out;
    s.out_size = out_size;
    do {
        unsigned type;
        last = (int)take_bits(&s, 1);
        type = take_bits(&s, 2);
        if (s.error) return (size_t)-1;
        if (block_types && type < 3) ++block_types[type];
        if (type == 0) {
            unsigned len, nlen;
            s.bit_count = 0;
            if (s.in_pos + 4 > s.in_size) return (size_t)-1;
            len = s.in[s.in_pos] | (unsigned)s.in[s.in_pos + 1] << 8;
            nlen = s.in[s.in_pos + 2] | (unsigned)s.in[s.in_pos + 3] << 8;
            s.in_pos += 4;
            if ((len ^ 0xFFFFu) != nlen || s.in_pos + len > s.in_size || s.out_pos + len > s.out_size) return (size_t)-1;
            memcpy(s.out + s.out_pos, s.in + s.in_pos, len);
            s.in_pos += len;
            s.out_pos += len;
        } else if (type == 1 || type == 2) {
            unsigned char lengths[320];
            huffman_table lit, dist;
            int nlit, ndist, ncode, k;
            if (type == 1) {
                for (k = 0; k < 288; ++k) lengths[k] = (unsigned char)(k < 144 ? 8 : k < 256 ? 9 : k < 280 ? 7 : 8);
                for (k = 0; k < 30; ++k) lengths[288 + k] = 5;
                nlit = 288;
                ndist = 30;
                build_table(&lit, lengths, nlit);
                /* The fixed distance code is not complete (30 of 32). */
                build_table(&dist, lengths + 288, ndist);
            } else {
                huffman_table code_table;
                unsigned char code_lengths[19];
                nlit = (int)take_bits(&s, 5) + 257;
                ndist = (int)take_bits(&s, 5) + 1;
                ncode = (int)take_bits(&s, 4) + 4;
                memset(code_lengths, 0, sizeof code_lengths);
                for (k = 0; k < ncode; ++k) code_lengths[order[k]] = (unsigned char)take_bits(&s, 3);
                if (s.error || !build_table(&code_table, code_lengths, 19)) return (size_t)-1;
                for (k = 0; k < nlit + ndist;) {
                    int symbol = decode_symbol(&s, &code_table), repeat, value = 0;
                    if (s.error) return (size_t)-1;
                    if (symbol < 16) { lengths[k++] = (unsigned char)symbol; continue; }
                    if (symbol == 16) {
                        if (k == 0) return (size_t)-1;
                        value = lengths[k - 1];
                        repeat = 3 + (int)take_bits(&s, 2);
                    } else if (symbol == 17) {
                        repeat = 3 + (int)take_bits(&s, 3);
                    } else {
                        repeat = 11 + (int)take_bits(&s, 7);
                    }
                    if (k + repeat > nlit + ndist) return (size_t)-1;
                    while (repeat-- > 0) lengths[k++] = (unsigned char)value;
                }
                if (!build_table(&lit, lengths, nlit) || !build_table(&dist, lengths + nlit, ndist)) return (size_t)-1;
            }
            if (!inflate_codes(&s, &lit, &dist)) return (size_t)-1;
        } else {
            return (size_t)-1;
        }
    } while (!last);
    /* Everything but the Adler-32 trailer was consumed. */
    if (s.in_pos != s.in_size) return (size_t)-1;
    for (i = 0; i < s.out_pos; ++i) {
        a = (a + out[i]) % 65521u;
        b = (b + a) % 65521u;
    }
    want = (uint32_t)in[in_size - 4] << 24 | (uint32_t)in[in_size - 3] << 16 | (uint32_t)in[in_size - 2] << 8 | in[in_size - 1];
    return ((b << 16) | a) == want ? s.out_pos : (size_t)-1;
}

/* A macro, so a test that only counts blocks has no unused function. */
#define zlib_inflate(in, in_size, out, out_size) zlib_inflate_blocks(in, in_size, out, out_size, NULL)

#endif
