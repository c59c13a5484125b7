/* rrv_vec3 from its three components, for tests that link against the
   compiled library (build/rrv_impl.o) and so cannot see the header's own
   rrv__v3; tests that compile the implementation in may use either. */
#ifndef RRV_TEST_VEC3_H
#define RRV_TEST_VEC3_H
static inline rrv_vec3 tv3(double x, double y, double z)
{
    rrv_vec3 v;
    v.x = x;
    v.y = y;
    v.z = z;
    return v;
}
#endif
