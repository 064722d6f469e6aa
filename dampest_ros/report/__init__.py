"""HTML reports, one directory each (index.html and PNG figures): a batch identification
(:mod:`.identify`), an online one (:mod:`.convergence`), built from shared figures, units and
styles (:mod:`.figures`). Never imports rclpy.
"""
