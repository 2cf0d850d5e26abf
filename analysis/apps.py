from django.apps import AppConfig


class AnalysisConfig(AppConfig):
    name = "analysis"
    verbose_name = "Analysis"

    def ready(self) -> None:
        from analysis import receivers
        from training.signals import trace_recorded

        trace_recorded.connect(receivers.summarize_recorded, dispatch_uid="analysis.summarize")
