"""Every compiled (numba) kernel of teleprev, one module per concern, on the ground floor:

    fk          forward kinematics of a joint tree
    ik          arm inverse kinematics, and the wrist-to-TCP target that feeds it
    boxes       the separating-axis test of two boxes, two margins in one pass
    collision   self-collision of an all-box robot (spheres cull, boxes decide)
    swept       the swept check of a hand command's segment
    motion      the hand's acceleration cap and the arm generator's arithmetic around ruckig
    glove       a glove sample's decoding, checks, finger angles and retargeting
    mlp         CPN / CCN inference and the Corrector's CCN step

Kernels take arrays and numbers only; the classes that use them build their tables. Importing this
package compiles nothing: each kernel compiles on its first call and is cached on disk.
"""
