/* The one translation unit that holds rrv's implementation. POSIX 2008
   before the first system header: the file readers and writers use open,
   fstat and fcntl where the platform has them (rrv.h, CONFIGURATION). */
#if !defined(_POSIX_C_SOURCE) && !defined(_XOPEN_SOURCE)
#define _POSIX_C_SOURCE 200809L
#endif
#define RRV_IMPLEMENTATION
#include "rrv.h"
