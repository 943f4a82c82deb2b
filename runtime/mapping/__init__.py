"""facepuppet.runtime.mapping: names onto targets. A tracker's channel names in any convention onto a
character's shapes (:mod:`.channels`: ARKit's 52, canonical spellings, ``ChannelMap``), onto a VRM avatar's
expressions (:mod:`.expressions`: ``ExpressionDrive``, ``[mapping]``), and onto the names VMC and VRM
receivers expect (:mod:`.vrm_names`).
"""
