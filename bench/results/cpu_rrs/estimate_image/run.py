import bench.converge as c
orig = c._method_params
c._method_params = lambda m: dict(orig(m), adrrs_estimate="image") if m == "adrrs" else orig(m)
c.main(["--npz", ".wt/npz160", "--width", "160", "--peers", "", "--seconds", "20", "--reference-seconds", "120",
        "--warm", "--append", "--out", "/tmp/conv_img", "--scenes", "light_behind_glass,cornell_box,sun_room,veach_mis,atrium",
        "--methods", "adrrs"])
