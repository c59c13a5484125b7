/* The one translation unit that holds rrv's implementation. */
#define RRV_IMPLEMENTATION
#include "rrv.h"
